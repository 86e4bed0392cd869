"""set_listen: handing joystick control of the legged robot to a client, and back (ROS-free).

Request strings (shared/seeds/003): ``"topic<&>client_id"`` hands control to ``client_id``'s
``sensor_msgs/Joy`` on ``topic``; ``"topic<&><CLOSE>"`` takes it back. While a client holds
control, its Joy messages drive the robot (the waypoint follower and velocity commands wait) and
``robot_state.joy_listen_type`` is JOY; otherwise it is VEL_CMD (velocity commands and the
waypoint follower drive) or NONE when the node listens to no velocity topic. A second client
while one holds control is refused with a message naming the holder; the holder may move to
another topic by asking again. A holder whose Joy messages stop for ``joy_timeout`` keeps
control but the robot stops until they resume.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

from lowerbase.text import clip

SEPARATOR = "<&>"
CLOSE = "<CLOSE>"


class JoyListenType(IntEnum):
    """robot_state.joy_listen_type."""

    JOY = 0
    VEL_CMD = 1
    NONE = 2


@dataclass(frozen=True)
class JoyMapping:
    """sensor_msgs/Joy axes -> body velocity (the ROS joy driver's gamepad layout)."""

    axis_vx: int = 1          # left stick up/down
    axis_vy: int = 0          # left stick left/right
    axis_wz: int = 3          # right stick left/right
    max_linear: float = 0.6   # m/s at full stick
    max_lateral: float = 0.3
    max_angular: float = 1.0  # rad/s
    deadzone: float = 0.05


@dataclass(frozen=True)
class Holder:
    topic: str
    client: str


#: a ROS graph resource name (wiki.ros.org/Names): global (/), relative or private (~), tokens
#: of letters, digits and '_' each starting with a letter, separated by single '/'
TOPIC_NAME = re.compile(r"(~|/)?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")


def parse(data: str) -> tuple[str, str]:
    """(topic, client or CLOSE) of a set_listen string; ValueError with what is wrong (the
    input quoted short: :func:`~lowerbase.text.clip`)."""
    topic, sep, client = data.partition(SEPARATOR)
    topic, client = topic.strip(), client.strip()
    if not sep or not topic or not client:
        raise ValueError(f"expected 'topic<&>client_id' or 'topic<&><CLOSE>', got {clip(data)}")
    if SEPARATOR in client:
        raise ValueError(f"one '<&>' expected, got {clip(data)}")
    if not TOPIC_NAME.fullmatch(topic):
        raise ValueError(f"{clip(topic)} is not a ROS topic name: letters, digits and '_' in "
                         "tokens that start with a letter, separated by single '/' (e.g. "
                         "'joy', '/ns/joy', '~joy')")
    return topic, client


class JoyHandover:
    """Who holds joystick control, and the velocity their Joy messages ask for."""

    def __init__(self, mapping: JoyMapping | None = None, *, joy_timeout: float = 0.5,
                 default_type: JoyListenType = JoyListenType.VEL_CMD) -> None:
        self.mapping = mapping or JoyMapping()
        self.joy_timeout = joy_timeout
        self.default_type = default_type
        self.holder: Holder | None = None
        self._command = (0.0, 0.0, 0.0)
        self._last_joy = -math.inf
        self.rejected_joy = 0

    @property
    def listen_type(self) -> JoyListenType:
        return JoyListenType.JOY if self.holder is not None else self.default_type

    def request(self, data: str) -> tuple[bool, str]:
        """set_listen: (success, message). The caller (re)subscribes to ``holder.topic``."""
        try:
            topic, client = parse(data)
        except ValueError as exc:
            return False, str(exc)
        held = self.holder
        if client == CLOSE:
            if held is None:
                return False, "joystick control is not handed over: nothing to close"
            if topic != held.topic:
                return False, (f"joystick control is on topic {held.topic!r}, not {clip(topic)}: "
                               f"send '{held.topic}{SEPARATOR}{CLOSE}'")
            self.holder = None
            self._command = (0.0, 0.0, 0.0)
            return True, f"joystick control taken back from {clip(held.client)}"
        if held is not None and held.client != client:
            return False, (f"joystick control is held by {clip(held.client)} on {held.topic!r}; "
                           f"it must release it first ('{held.topic}{SEPARATOR}{CLOSE}')")
        self.holder = Holder(topic, client)
        self._command = (0.0, 0.0, 0.0)
        self._last_joy = -math.inf
        return True, f"joystick control handed to {clip(client)} on topic {clip(topic)}"

    def on_joy(self, topic: str, axes: Sequence[float], now: float) -> bool:
        """A Joy message from ``topic``; False (counted) unless it is the holder's."""
        m = self.mapping
        if self.holder is None or topic != self.holder.topic:
            self.rejected_joy += 1
            return False
        values = []
        for index, limit in ((m.axis_vx, m.max_linear), (m.axis_vy, m.max_lateral),
                             (m.axis_wz, m.max_angular)):
            a = float(axes[index]) if index < len(axes) else 0.0
            if not math.isfinite(a) or abs(a) < m.deadzone:
                a = 0.0
            values.append(max(-1.0, min(1.0, a)) * limit)
        self._command = (values[0], values[1], values[2])
        self._last_joy = now
        return True

    def command(self, now: float) -> tuple[float, float, float] | None:
        """The holder's velocity (zero once their Joy is stale), or None when nobody holds."""
        if self.holder is None:
            return None
        if now - self._last_joy > self.joy_timeout:
            return 0.0, 0.0, 0.0
        return self._command
