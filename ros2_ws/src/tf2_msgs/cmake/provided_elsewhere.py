"""Exit 0 when a tf2_msgs outside this workspace is already installed, else 1.

``make setup`` skips building the workspace's tf2_msgs when this says 0, so that on a full
ROS 2 install (``source /opt/ros/jazzy/setup.bash``) the system's package is used and never
shadowed. Looks for ``share/tf2_msgs/package.xml`` under every ``AMENT_PREFIX_PATH`` entry that
is not inside this repository (the project's own venv and colcon install are inside it).
"""
import os
from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[4]


def provided_elsewhere() -> bool:
    """Return True when a prefix outside the repository provides tf2_msgs."""
    for entry in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if not entry:
            continue
        prefix = Path(entry).resolve()
        if prefix == ROOT or ROOT in prefix.parents:
            continue
        if (prefix / 'share' / 'tf2_msgs' / 'package.xml').is_file():
            return True
    return False


if __name__ == '__main__':
    sys.exit(0 if provided_elsewhere() else 1)
