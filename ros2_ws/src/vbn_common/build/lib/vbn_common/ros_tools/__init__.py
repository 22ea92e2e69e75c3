"""The rclpy glue of the bag tools: ``vbn play``, ``vbn record`` and ``vbn echo``.

These are the only modules of vbn_common's bag tools that import rclpy or
message packages; the bag reading and writing they use is in
:mod:`vbn_common.bags`.
"""

# Checked on import, before any module of this package imports rclpy: with an
# RMW_IMPLEMENTATION that is not installed, rcl ends the process (exit 102) while its
# library loads, so a check at rclpy.init would come too late.
from vbn_common.ros_environment import check_ros_environment

check_ros_environment()
