"""The navigation module of shared/seeds/001 (docs/trace.md): TraceNavigate follows a list of
directed segments, ObstacleNavigate goes around what blocks it; both speak the seed's protobuf
messages (``proto/trace.proto``) on the seed's topics. The cores are ROS-free on an injected
clock; ``node`` is the thin rospy layer, ``sim`` runs them on the simulated chassis."""
