"""actionlib's ``SimpleActionServer`` as the navigation face uses it, on ``rclpy.action``:
:class:`SimpleActionServer` (made by :meth:`lowerbase.ros2.wire.Ros2Wire.action_server`).

The face's execute callback runs as on ROS 1: one goal at a time, in a thread of its own (here
one of the executor's, in a reentrant callback group), following the goal until it calls
``set_succeeded``/``set_aborted``/``set_preempted``; ``is_preempt_requested`` says a cancel
came or a newer goal is waiting (``is_new_goal_available``), as actionlib's simple policy.

ROS 2 actions have fewer states than actionlib, so the ends are mapped so:

- SUCCEEDED -> SUCCEEDED; ABORTED -> ABORTED.
- PREEMPTED after a cancel request -> CANCELED. PREEMPTED by a newer goal (no cancel asked)
  -> ABORTED: a ROS 2 goal can only be CANCELED after its client asked for it.
- A goal superseded by a newer one before it ran -> ABORTED (actionlib: PREEMPTED).
- ROS 2 has no status text: the text the face gives goes to the log, and into the result's
  ``error_msg`` where the result has one (nav2's).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)


class _Inner:
    """What the face reads of actionlib's inner ``ActionServer``: ``lock``, ``started``."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.started = False

    def publish_status(self) -> None:
        """ROS 2 publishes the status itself (no text to publish)."""


class _NoTracker:
    """actionlib's ``current_goal``: no status tracker, since a ROS 2 goal has no text."""

    status_tracker = None


class SimpleActionServer:
    """See the module docstring; ``name`` is resolved by rclpy (``~/x`` is private)."""

    def __init__(self, node: Any, name: str, action_type: Any,
                 execute_cb: Callable[[Any], None], auto_start: bool = False) -> None:
        from rclpy.action import ActionServer, CancelResponse, GoalResponse
        from rclpy.callback_groups import ReentrantCallbackGroup

        self.name, self.action_type, self.execute_cb = name, action_type, execute_cb
        self.action_server = _Inner()
        self.current_goal = _NoTracker()
        self._cond = threading.Condition()
        self._current: Any = None  #: the goal handle the face is following
        self._latest: Any = None  #: the newest accepted goal handle
        self._outcome: tuple[str, Any, str] | None = None
        self.server = ActionServer(
            node, action_type, name, self._execute,
            callback_group=ReentrantCallbackGroup(),
            goal_callback=lambda _goal: (GoalResponse.ACCEPT if self.action_server.started
                                         else GoalResponse.REJECT),
            handle_accepted_callback=self._accepted,
            cancel_callback=lambda _request: CancelResponse.ACCEPT)
        if auto_start:
            self.start()

    def start(self) -> None:
        self.action_server.started = True

    def shutdown(self) -> None:
        self.action_server.started = False
        self.server.destroy()

    # -- rclpy's side ---------------------------------------------------------------------------
    def _accepted(self, handle: Any) -> None:
        with self._cond:
            self._latest = handle
            self._cond.notify_all()
        handle.execute()

    def _execute(self, handle: Any) -> Any:
        with self._cond:
            while self._current is not None and handle is self._latest:
                self._cond.wait(0.1)
            if handle is not self._latest or handle.is_cancel_requested:
                self._end(handle, ("preempted", None, "preempted before it ran"))
                return self.action_type.Result()
            self._current, self._outcome = handle, None
        try:
            self.execute_cb(handle.request)
        finally:
            with self._cond:
                outcome = self._outcome or ("aborted", None, "the goal was left without a "
                                            "result")
                self._current = None
                self._cond.notify_all()
        return self._end(handle, outcome)

    def _end(self, handle: Any, outcome: tuple[str, Any, str]) -> Any:
        state, result, text = outcome
        result = result if result is not None else self.action_type.Result()
        if text and state != "succeeded" and hasattr(result, "error_msg") and \
                not result.error_msg:
            result.error_msg = text
        if state == "succeeded":
            handle.succeed()
        elif state == "preempted" and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        (log.info if state == "succeeded" else log.warning)(
            "%s goal %s%s", self.name, state, f": {text}" if text else "")
        return result

    # -- the face's side (actionlib's calls) ----------------------------------------------------
    def is_active(self) -> bool:
        with self._cond:
            return self._current is not None and self._outcome is None

    def is_new_goal_available(self) -> bool:
        with self._cond:
            return self._latest is not None and self._latest is not self._current

    def is_preempt_requested(self) -> bool:
        with self._cond:
            current = self._current
            if current is None:
                return False
            return bool(current.is_cancel_requested) or self._latest is not current

    def publish_feedback(self, feedback: Any) -> None:
        with self._cond:
            current = self._current if self._outcome is None else None
        if current is not None:
            current.publish_feedback(feedback)

    def _set(self, state: str, result: Any, text: str) -> None:
        with self._cond:
            if self._current is not None and self._outcome is None:
                self._outcome = (state, result, text)

    def set_succeeded(self, result: Any = None, text: str = "") -> None:
        self._set("succeeded", result, text)

    def set_aborted(self, result: Any = None, text: str = "") -> None:
        self._set("aborted", result, text)

    def set_preempted(self, result: Any = None, text: str = "") -> None:
        self._set("preempted", result, text)
