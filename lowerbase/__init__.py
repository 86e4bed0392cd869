"""lowerbase: a virtual lower computer for differential-drive AMR chassis.

The chassis MCU (motors, encoders, IMU, BMS relay, LED strips) emulated behind the same CAN or
serial wire protocol as the real one, described once in ``lowerbase/protocol/chassis.dbc``.
"""

__version__ = "0.1.0"
