"""Recordings of runs as MCAP files that Foxglove (and any MCAP reader) opens: ``--record`` of ``hrc
dispatch``, ``hrc console``, ``hrc ros2`` and ``hrc simulate`` (docs/record.md).

Channels (Foxglove's well-known schemas, protobuf-encoded, where one fits; JSON with a JSON Schema for
hrc's own messages). Times are run seconds from the task's start; every entity and pose is in the
frame ``map`` (hrc's map coordinates, metres):

==================== ==================== ===========================================================
topic                schema               what
==================== ==================== ===========================================================
/hrc/map             foxglove.SceneUpdate the shop floor once, at 0: slab, walls, obstacles, locations
/hrc/routes          foxglove.SceneUpdate each agent's route in the best plan, whenever the plan changes
/hrc/agents          foxglove.SceneUpdate both agents as discs with a label: where, what; the robot's
                                          next step and its window
/hrc/human/pose      foxglove.PoseInFrame the person's position (measured in a simulation; else where
/hrc/robot/pose                           last seen), and the robot's
/hrc/robot/goal      foxglove.PoseInFrame the robot's next drive's destination, then its way home (as
                                          ``hrc ros2`` sends them)
/hrc/in              hrc.Message (JSON)   each message given to the dispatcher, as received
/hrc/out             hrc.Answer (JSON)    each answer, as given out
/hrc/decision        hrc.Decision (JSON)  after each accepted message: plan, class, class_rank,
                                          candidates per class, the robot's window (for plots)
/hrc/log             foxglove.Log         the messages (``in``) and answers (``out``) as text lines
==================== ==================== ===========================================================

With ``--record-format ros2`` the same topics carry ROS 2 message types instead (`ros2msg`:
std_msgs/String, geometry_msgs/PoseStamped, visualization_msgs/MarkerArray; no /hrc/log), for ``ros2 bag``
and RViz.

Modules: `scene` (the Foxglove messages drawn), `ros2msg` (the ROS 2 ones), `recorder` (`RunRecorder`,
`Recording`: a run into a file), `sim` (recording simulated runs).
"""

from hrc.record.recorder import CLASS_RANK, FORMATS, FRAME_PERIOD, Recording, RunRecorder, open_folder_recording

__all__ = ["CLASS_RANK", "FORMATS", "FRAME_PERIOD", "Recording", "RunRecorder", "open_folder_recording"]
