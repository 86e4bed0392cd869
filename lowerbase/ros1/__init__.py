"""The rospy faces' plumbing: a ROS 1 session (master, loopback, node name) and the wire that
publishes, subscribes and serves on an injected clock. Nothing here knows a robot part."""
