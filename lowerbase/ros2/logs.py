"""lowerbase's log records on ROS 2: :class:`ToRclpy` hands them to the node's rclpy logger,
which prints them and publishes them on /rosout (rcl_interfaces/msg/Log), as
:class:`lowerbase.ros1.node.ToRosout` does with rospy's on ROS 1."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from typing import Any

#: Python's levels as rclpy's severities (rclpy.logging.LoggingSeverity's values)
SEVERITY = ((logging.CRITICAL, 50), (logging.ERROR, 40), (logging.WARNING, 30),
            (logging.INFO, 20), (logging.DEBUG, 10))


def severity(level: int) -> int:
    """The rclpy severity of a Python level (the nearest at or below it)."""
    return next((s for lvl, s in SEVERITY if level >= lvl), 10)


class ToRclpy(logging.Handler):
    """Hands each record to ``node``'s logger (console and /rosout). A record that rclpy can
    no longer take (its context shut down) goes to stderr."""

    def __init__(self, node: Any) -> None:
        super().__init__()
        self.logger = node.get_logger()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
            if record.exc_info:
                text += "\n" + logging.Formatter().formatException(record.exc_info)
            # one call site per severity: rclpy refuses ("Logger severity cannot be changed
            # between calls") one site that logs at several
            level = severity(record.levelno)
            if level >= 50:
                self.logger.fatal(text)
            elif level >= 40:
                self.logger.error(text)
            elif level >= 30:
                self.logger.warning(text)
            elif level >= 20:
                self.logger.info(text)
            else:
                self.logger.debug(text)
        except Exception:  # rclpy shut down, or a record it refuses: not lost, not raised
            sys.stderr.write(f"{record.levelname}: {record.getMessage()}\n")


def to_rosout(node: Any) -> Callable[[], None]:
    """lowerbase's records go to ``node``'s logger from now on; returns what undoes it."""
    logger = logging.getLogger("lowerbase")
    handler = ToRclpy(node)
    logger.addHandler(handler)
    saved, logger.propagate = logger.propagate, False

    def undo() -> None:
        logger.removeHandler(handler)
        logger.propagate = saved

    return undo
