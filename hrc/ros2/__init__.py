"""`hrc ros2`: one dispatcher on ROS 2 topics (docs/ros2.md), an optional extra (``pip install 'hrc[ros2]'``).

Modules: `topics` (names, types, QoS: what docs/ros2.md lists), `drive` (the robot's next drive and the
map frame: pure, shared with the MCAP recorder), `node` (the rclpy node holding the dispatcher; the only
module that imports ROS). Nothing here imports ``rclpy`` at import time but `node`, so that the rest
serves without the extra.
"""

__all__: list[str] = []
