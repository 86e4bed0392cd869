"""The legged robot's driver: its ROS-free core (the lower computer's state machine seen from
the upper computer, waypoints, joystick, point-cloud maps) and its rospy face."""
