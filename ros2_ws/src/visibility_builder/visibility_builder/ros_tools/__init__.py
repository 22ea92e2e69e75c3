"""The rclpy glue of the bag tools: ``vbn play``, ``vbn record`` and ``vbn echo``.

These are the only modules of visibility_builder's bag tools that import rclpy or
message packages; the bag reading and writing they use is in
:mod:`visibility_builder.bag_io`.
"""
