"""A stand-alone 'test process' for the domain isolation test.

Publishes ``<tag>:<i>`` on /vbn_isolation at 50 Hz and subscribes to the same topic
on the domain given by ROS_DOMAIN_ID. Runs until it has received ``--own`` of its own
messages, for at least ``--min-seconds``, and (with ``--expect-foreign``) until it
has also seen a message of another tag; then prints one JSON line with what it saw,
including the most publishers on the topic that its graph ever showed.
"""
from __future__ import annotations

import argparse
import json
import os
import time

import rclpy
from std_msgs.msg import String

parser = argparse.ArgumentParser()
parser.add_argument('tag')
parser.add_argument('--own', type=int, default=50)
parser.add_argument('--min-seconds', type=float, default=0.0)
parser.add_argument('--expect-foreign', action='store_true')
parser.add_argument('--timeout', type=float, default=60.0)
args = parser.parse_args()

rclpy.init()
node = rclpy.create_node(f'isolation_{args.tag}')
own: list[str] = []
foreign: list[str] = []


def on_message(msg: String) -> None:
    (own if msg.data.startswith(args.tag + ':') else foreign).append(msg.data)


pub = node.create_publisher(String, '/vbn_isolation', 10)
node.create_subscription(String, '/vbn_isolation', on_message, 10)
start = time.monotonic()
first_foreign_s = None
count = 0
next_pub = start
max_publishers = 0
while time.monotonic() - start < args.timeout:
    now = time.monotonic()
    if now >= next_pub:
        pub.publish(String(data=f'{args.tag}:{count}'))
        count += 1
        next_pub = now + 0.02
        max_publishers = max(max_publishers, node.count_publishers('/vbn_isolation'))
    rclpy.spin_once(node, timeout_sec=0.005)
    if foreign and first_foreign_s is None:
        first_foreign_s = time.monotonic() - start
    done = (len(own) >= args.own and time.monotonic() - start >= args.min_seconds
            and (foreign or not args.expect_foreign))
    if done:
        break
print(json.dumps({
    'tag': args.tag, 'domain': int(os.environ.get('ROS_DOMAIN_ID', '0')),
    'own': len(own), 'foreign': len(foreign), 'foreign_tags': sorted(
        {m.split(':')[0] for m in foreign}), 'publishers': max_publishers,
    'first_foreign_s': first_foreign_s, 'seconds': time.monotonic() - start,
}), flush=True)
node.destroy_node()
rclpy.try_shutdown()
