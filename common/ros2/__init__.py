"""ROS 2 over Zenoh without a ROS install: rmw_zenoh's wire format (:mod:`.rmw_format`), the
teleoperation's figures as standard ROS 2 messages (:mod:`.messages`), and the thread that
publishes them off the control loop to a ROS 2 graph through rmw_zenohd (:mod:`.publisher`).
docs/ros2.md says how a ROS 2 user sees and records a session."""
