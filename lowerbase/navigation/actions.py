"""The navigation node's actionlib servers: /move_base, /cmd_vel_control, /navigation_mode.

Each is an ``actionlib.SimpleActionServer`` (Debian's python3-actionlib) whose goal thread only
starts work on the :class:`~lowerbase.navigation.node.NavigationNode`'s controllers and then
follows them tick by tick (it waits on the node's ``ticked`` condition, notified every control
period): feedback every period, the result when the controller says so.

- /move_base (woosh_msgs/MoveBaseAction): SUCCEEDED at the goal; ABORTED with the reason in the
  status text (no path, stuck, a bad goal); PREEMPTED on cancel or a newer goal (actionlib's
  simple-server policy). Feedback: ``base_position`` (the robot in the map frame). While the
  navigator reports its path BLOCKED, the ACTIVE goal's status text (in /move_base/status, and
  a SimpleActionClient's ``get_goal_status_text()``) is ``path blocked: <reason>``
  (:data:`BLOCKED_TEXT`), published at once, and back to the accepted text on the first free
  tick; the messages stay the vendor's (no field added). ``lowerbase tasks`` reads it.
- /cmd_vel_control (woosh_msgs/StepControlAction): ``mode`` EXCUTE starts a list, PAUSE/RESUM
  act on the running one, CANCEL ends it. A new goal supersedes the goal handle that was
  following the list (that handle ends PREEMPTED); a PAUSE/RESUM goal follows the list to its
  end and carries its result. An actionlib cancel brakes and ends the list (result -2). A
  refused goal (empty list, NaN, out of range, LATERAL/DIAGONALIZE, or PAUSE/RESUM/CANCEL with
  nothing running) is ABORTED with ``result`` -1 and the reason as the status text; it also
  brakes a list that was running, so the robot stands still. A step still more than 2 cm /
  1 deg off after its corrections, or stalled (no progress for 4 s), ends the list ABORTED with
  ``result`` -3 and the reason. A RESUM goal's step list replaces the remaining steps.
- /navigation_mode (woosh_msgs/NavigationModeAction): SUCCEEDED with ``result`` 1, or ABORTED
  with ``result`` 0 and the reason.

A step list and a move_base goal never drive at once: an accepted EXCUTE cancels the move_base
goal (PREEMPTED), a move_base goal cancels a running step list (result -2).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from lowerbase.errors import LowerbaseError, WorldError
from lowerbase.navigation.controller import Status
from lowerbase.navigation.steps import CANCEL, CANCELLED, EXCUTE, MODE_NAMES, REJECTED, Step

log = logging.getLogger(__name__)

#: the goal thread re-checks at least this often even without a tick [s]
WAKE = 0.5
#: the ACTIVE /move_base goal's status text starts so while its path is blocked
BLOCKED_TEXT = "path blocked: "


class ActionServers:
    """The three servers around one node (rospy already initialised)."""

    def __init__(self, node: Any) -> None:
        from woosh_msgs.msg import MoveBaseAction, NavigationModeAction, StepControlAction

        self.node = node
        self.step_generation = 0  #: +1 per accepted EXCUTE (which list a goal follows)
        self.goal_generation = 0  #: +1 per goal sent to the navigator (which goal one follows)
        wire = node.wire
        server = wire.action_server  # actionlib's SimpleActionServer (or ROS 2's adapter)
        self.move_base = server(wire.node_name, MoveBaseAction, self._move_base,
                                auto_start=False)
        self.steps = server(wire.resolve("cmd_vel_control"), StepControlAction,
                            self._step_control, auto_start=False)
        self.mode = server(wire.resolve("navigation_mode"), NavigationModeAction,
                           self._navigation_mode, auto_start=False)

    def start(self) -> None:
        for server in (self.move_base, self.steps, self.mode):
            server.start()
        self.node.rospy.on_shutdown(self.quiet)

    def quiet(self) -> None:
        """Stop the servers' timed status publishing, as rospy begins to shut down.

        rospy runs ``on_shutdown`` hooks before it raises its shutdown flag and closes the
        topics; actionlib's status timer checks only that flag, so a tick in between published
        to a closed topic and left a traceback in the log. Taking each server's lock waits for
        a tick in flight; ``started`` False makes the next ones return."""
        for server in (self.move_base, self.steps, self.mode):
            inner = server.action_server
            with inner.lock:
                inner.started = False

    def shutdown(self) -> None:
        for server in (self.move_base, self.steps, self.mode):
            if server.is_active():
                server.set_aborted(text="the navigation node is shutting down")

    def _wait_tick(self, seen: int) -> int:
        """Wait for a control tick after ``seen``; the node's current tick count."""
        node = self.node
        with node.ticked:
            if node.tick_count == seen and not node.stop.is_set():
                node.ticked.wait(WAKE)
            return int(node.tick_count)

    # -- /move_base --------------------------------------------------------------------------
    def _move_base(self, goal: Any) -> None:
        from woosh_msgs.msg import MoveBaseFeedback

        node, io, server = self.node, self.node.io, self.move_base
        frame = node.setup.map_frame

        def feedback(pose: tuple[float, float, float]) -> None:
            server.publish_feedback(MoveBaseFeedback(
                base_position=io.pose_stamped(pose, node.rospy.Time.now(), frame)))

        try:
            target = io.stamped_pose(goal.target_pose, "target_pose", (frame,))
            poses = [io.stamped_pose(p, f"poses[{i}]", (frame,))
                     for i, p in enumerate(goal.poses)]
        except LowerbaseError as exc:
            log.warning("move_base goal refused: %s", exc)
            server.set_aborted(text=str(exc))
            return
        self.drive(server, "move_base", target, poses, int(goal.execution_mode), feedback)

    def drive(self, server: Any, name: str, target: tuple[float, float, float],
              poses: list[Any], mode: int,
              feedback: Callable[[tuple[float, float, float]], None],
              result: Callable[[str], Any] = lambda _state: None) -> None:
        """Send a goal to the navigator and follow it for ``server`` (a SimpleActionServer's
        execute callback) until it ends: ``feedback`` with the robot's map pose every tick,
        the end with ``result(state)`` ("succeeded", "aborted", "preempted") and the reason as
        the status text. The /move_base server also shows a blocked path in its goal's text.
        A goal sent by another server (nav2's ``navigate_to_pose``) preempts this one."""
        from lowerbase.navigation.navigator import GoalState

        node = self.node
        try:
            with node.lock:
                if node.steps.active:
                    node.steps.goal(CANCEL)
                node.last_command = None
                node.navigator.send_goal(target, poses, mode, node.now())
                self.goal_generation += 1
                generation = self.goal_generation
        except LowerbaseError as exc:
            log.warning("%s goal refused: %s", name, exc)
            server.set_aborted(result("aborted"), text=str(exc))
            return
        log.info("%s: goal (%.2f, %.2f, %.2f), %d path poses", name, *target, len(poses))
        texts = server is self.move_base
        seen = node.tick_count
        accepted = shown = self._goal_text() if texts else ""
        while True:
            seen = self._wait_tick(seen)
            if node.stop.is_set():
                server.set_aborted(result("aborted"),
                                   text="the navigation node is shutting down")
                return
            with node.lock:
                pose = node.map_pose()
                if generation != self.goal_generation:
                    server.set_preempted(result("preempted"),
                                         text="preempted: a goal of another server")
                    return
                if server.is_preempt_requested():
                    node.navigator.cancel(node.now())
                    why = "a newer goal" if server.is_new_goal_available() else "cancelled"
                    server.set_preempted(result("preempted"), text=f"preempted: {why}")
                    return
                state, reason = node.navigator.state, node.navigator.reason
                command = node.last_command
            if pose is not None:
                feedback(pose)
            if state == GoalState.SUCCEEDED:
                server.set_succeeded(result("succeeded"), text="goal reached")
                return
            if state == GoalState.ABORTED:
                server.set_aborted(result("aborted"), text=reason)
                return
            if state == GoalState.PREEMPTED:
                server.set_preempted(result("preempted"), text=reason)
                return
            text = accepted
            if command is not None and command.status is Status.BLOCKED:
                text = BLOCKED_TEXT + (command.reason or "an obstacle")
            elif command is not None and command.status is Status.WAITING:
                text = command.reason
            if texts and text != shown:
                shown = text
                self._set_goal_text(text)

    def _goal_text(self) -> str:
        """The current /move_base goal's status text."""
        with self.move_base.action_server.lock:
            tracker = self.move_base.current_goal.status_tracker
            return str(tracker.status.text) if tracker is not None else ""

    def _set_goal_text(self, text: str) -> None:
        """Set the ACTIVE /move_base goal's status text and publish /move_base/status now.

        SimpleActionServer has no call for this (a text goes with a transition only), so the
        goal handle's status is changed under the server's lock, as its own calls do; nothing
        is published once the server is quiet (shutting down) or the goal has ended."""
        inner = self.move_base.action_server
        with inner.lock:
            tracker = self.move_base.current_goal.status_tracker
            if not inner.started or tracker is None:  # ROS 2's goals have no text
                return
            from actionlib_msgs.msg import GoalStatus  # type: ignore[import-untyped]

            if tracker.status.status != GoalStatus.ACTIVE:
                return
            tracker.status.text = text
            inner.publish_status()

    # -- /cmd_vel_control ----------------------------------------------------------------------
    def _step_control(self, goal: Any) -> None:
        from woosh_msgs.msg import StepControlResult

        node, server = self.node, self.steps
        mode = int(goal.mode)
        steps = [Step(int(s.executeMode), float(s.data), float(s.speed), float(s.angle))
                 for s in goal.stepControl]
        with node.lock:
            ctrl = node.steps
            if mode != EXCUTE and mode in MODE_NAMES and not ctrl.active:
                refused = f"{MODE_NAMES[mode]}: no step list is running"
                first = 0
            else:
                rejection = ctrl.goal(mode, steps, bool(goal.useAvoid))
                refused = rejection.message if rejection is not None else ""
                first = rejection.execute_mode if rejection is not None else 0
                if refused and ctrl.active:
                    ctrl.goal(CANCEL)  # a refused goal leaves the robot standing
            if not refused and mode == EXCUTE:
                self.step_generation += 1
                if node.navigator_active():
                    node.navigator.cancel(node.now())
            generation = self.step_generation
        if refused:
            log.warning("cmd_vel_control goal refused: %s", refused)
            server.set_aborted(StepControlResult(result=REJECTED, executeMode=first,
                                                 percent=0.0), text=refused)
            return
        if mode == CANCEL:
            res = ctrl.result
            server.set_succeeded(StepControlResult(result=CANCELLED,
                                                   executeMode=res.execute_mode if res else 0,
                                                   percent=res.percent if res else 0.0),
                                 text="step list cancelled")
            return
        self._follow_steps(generation)

    def _follow_steps(self, generation: int) -> None:
        from woosh_msgs.msg import StepControlFeedback, StepControlResult

        node, server = self.node, self.steps
        seen = node.tick_count
        while True:
            seen = self._wait_tick(seen)
            with node.lock:
                ctrl = node.steps
                superseded = generation != self.step_generation
                if node.stop.is_set():
                    ctrl.goal(CANCEL)
                    server.set_aborted(text="the navigation node is shutting down")
                    return
                if server.is_preempt_requested():
                    if server.is_new_goal_available() or superseded:
                        server.set_preempted(StepControlResult(
                            result=0, executeMode=ctrl.mode, percent=ctrl.percent),
                            text="superseded by a newer StepControl goal")
                        return
                    ctrl.goal(CANCEL)  # an actionlib cancel: brake and end the list
                res, fb = ctrl.result, ctrl.feedback
            if superseded or (res is None and fb is None and not ctrl.active):
                server.set_aborted(StepControlResult(result=0), text="the step list was "
                                   "replaced or ended elsewhere")
                return
            if res is not None:
                out = StepControlResult(result=res.result, executeMode=res.execute_mode,
                                        percent=res.percent)
                if res.result == CANCELLED:
                    server.set_preempted(out, text=res.message)
                elif res.result < 0:  # FAILED: a step stayed off after its corrections
                    server.set_aborted(out, text=res.message)
                else:
                    server.set_succeeded(out, text=res.message)
                return
            if fb is not None:
                server.publish_feedback(StepControlFeedback(
                    feedback=fb.feedback, executeMode=fb.execute_mode, percent=fb.percent))

    # -- /navigation_mode ----------------------------------------------------------------------
    def _navigation_mode(self, goal: Any) -> None:
        from woosh_msgs.msg import NavigationModeResult

        from lowerbase.navigation.modes import NavigationModeGoal

        node, server = self.node, self.mode
        try:
            request = NavigationModeGoal(
                navigation_mode=int(goal.navigation_mode),
                waiting_timeout=float(goal.waiting_timeout), max_speed=float(goal.max_speed),
                id=int(goal.id), permitted_passage=bool(goal.permitted_passage),
                capacity=int(goal.capacity), nav_dir=int(goal.nav_dir))
            with node.lock:
                ok, message = node.navigator.set_mode(request)
        except (LowerbaseError, WorldError, ValueError) as exc:
            ok, message = False, str(exc)
        if ok:
            server.set_succeeded(NavigationModeResult(result=1), text=message)
        else:
            log.warning("navigation_mode refused: %s", message)
            server.set_aborted(NavigationModeResult(result=0), text=message)
