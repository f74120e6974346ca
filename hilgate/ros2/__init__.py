"""hilgate as a ROS 2 participant over DDS (Cyclone DDS, the ``ros2`` extra), without a ROS installation:
the messages and their type hashes (:mod:`.messages`, pure), their DDS classes (:mod:`.idl`), the
participant (:mod:`.participant`), a vehicle's pose from a topic (:mod:`.poses`), links for ROS 2 nodes
(:mod:`.door`) and what hilgate publishes (:mod:`.publish`).  docs/ros2.md says how to use it.

Only the daemon imports this package, and only when a scene uses ROS 2: without the extra, hilgate
runs as before and a scene that asks for ROS 2 is refused in one line (:mod:`hilgate.scene.ros2`).
"""
