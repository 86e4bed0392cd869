"""The emulated lower computer: physics (kinematics, motors, encoders, IMU, ground truth),
the robot profile, parameters, fault injection and the MCU state machine that ties them to the
wire protocol."""
