"""``--record-format``, as ``hrc dispatch``, ``hrc console`` and ``hrc ros2`` offer it with ``--record``."""

from __future__ import annotations

import argparse

__all__ = ["RECORD_FORMATS", "add_record_format"]

RECORD_FORMATS = ("foxglove", "ros2")
"""`hrc.record.FORMATS`, spelled out here so that parsing the command line loads no MCAP writer (a test
holds the two equal)."""


def add_record_format(p: argparse.ArgumentParser) -> None:
    p.add_argument("--record-format", choices=RECORD_FORMATS, default="foxglove",
                   help="with --record: foxglove (Foxglove's schemas, the default) or ros2 (ROS 2 message types: "
                        "std_msgs/String, geometry_msgs/PoseStamped, visualization_msgs/MarkerArray, for "
                        "ros2 bag and RViz; Foxglove reads both)")
