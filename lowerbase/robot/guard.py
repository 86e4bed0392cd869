"""``python -m lowerbase.robot.guard PARENT_PID COMMAND...``: run COMMAND so that it gets
SIGTERM when the process PARENT_PID dies, however it dies (SIGKILL included), and does not
start at all when that process is gone already.

``lowerbase robot`` starts every part through it (:mod:`lowerbase.robot.supervisor`), so no
part outlives its robot: prctl(PR_SET_PDEATHSIG) is kept across execve, so this process
becomes COMMAND with the setting in place (Linux; elsewhere COMMAND runs without it).
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

#: prctl(2)'s option: the signal a process gets when the thread that forked it ends
PR_SET_PDEATHSIG = 1


def main(argv: list[str]) -> int:
    if len(argv) < 2 or not argv[0].isdigit():
        print("usage: python -m lowerbase.robot.guard PARENT_PID COMMAND...", file=sys.stderr)
        return 2
    parent, command = int(argv[0]), argv[1:]
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:  # the robot died before the setting took hold
        return 1
    try:
        os.execvp(command[0], command)
    except OSError as exc:
        print(f"lowerbase robot: cannot start {command[0]}: {exc.strerror or exc}",
              file=sys.stderr)
        return 127
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
