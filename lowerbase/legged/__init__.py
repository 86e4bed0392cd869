"""The emulated lower computer of a quadruped (12 MIT mini-cheetah actuators on four leg
buses, a body controller, battery and BMS), ROS-free; see docs/legged.md."""
