"""The simulated loop: a lower computer and its driver core back to back on one simulated clock
(SimLoop, SteppedLoop, TickedLoop; the legged LeggedSimLoop) and the truth hooks that read
the emulator's ground truth."""
