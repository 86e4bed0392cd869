"""The ROS 1 names the faces use, given to the ROS 2 types (:func:`ros1_names`), and
:class:`AnyStampIo`, a message-builder module that takes :class:`~lowerbase.ros2.wire.Stamp`.

The faces of the world, navigation and the tasks are written against rospy's generated
Python: a service handler returns ``SetBoolResponse``, the action types are
``MoveBaseAction``/``MoveBaseFeedback`` in ``woosh_msgs.msg``, and a received stamp is read
with ``msg.header.stamp.to_sec()``. ROS 2 has the same messages under other names
(``SetBool.Response``, ``woosh_msgs.action.MoveBase.Feedback``) and a ``builtin_interfaces/
Time`` without ``to_sec``. :func:`ros1_names` adds those names to the ROS 2 modules (aliases of
the ROS 2 classes, nothing else), once per process, so the faces run unchanged. Only the ROS 2
processes of lowerbase call it (``lowerbase robot --ros2``). :func:`legged_ros` is the legged
driver's face's :func:`~lowerbase.legged_driver.node.import_ros` on ROS 2.
"""

from __future__ import annotations

import importlib
from types import ModuleType, SimpleNamespace
from typing import Any

#: srv modules whose services the faces answer: ``XResponse``/``XRequest`` are added
SRV_MODULES = ("std_srvs.srv", "nav_msgs.srv", "woosh_msgs.srv", "lowerbase_legged_msgs.srv",
               "lowerbase_sim_msgs.srv")
#: the action packages whose ``<Name>Action``, ``Goal``, ``Result``, ``Feedback`` go to .msg
ACTION_PACKAGES = ("woosh_msgs",)

_done = False


def _time_to_sec(self: Any) -> float:
    return float(self.sec) + float(self.nanosec) * 1e-9


def ros1_names() -> None:
    """Add the ROS 1 names (see the module docstring); idempotent."""
    global _done
    if _done:
        return
    from builtin_interfaces.msg import Duration, Time

    for cls in (Time, Duration):
        if not hasattr(cls, "to_sec"):
            cls.to_sec = _time_to_sec
    for name in SRV_MODULES:
        module = importlib.import_module(name)
        for attr in list(vars(module)):
            srv = getattr(module, attr)
            if isinstance(srv, type) and hasattr(srv, "Request") and hasattr(srv, "Response"):
                setattr(module, f"{attr}Request", srv.Request)
                setattr(module, f"{attr}Response", srv.Response)
    for package in ACTION_PACKAGES:
        msg = importlib.import_module(f"{package}.msg")
        actions = importlib.import_module(f"{package}.action")
        for attr in list(vars(actions)):
            action = getattr(actions, attr)
            if isinstance(action, type) and hasattr(action, "Feedback"):
                setattr(msg, f"{attr}Action", action)
                for part in ("Goal", "Result", "Feedback"):
                    setattr(msg, f"{attr}{part}", getattr(action, part))
    _done = True


def legged_ros(rospy: Any) -> SimpleNamespace:
    """What :class:`~lowerbase.legged_driver.node.LeggedNode` takes as ``ros`` on ROS 2: the
    names of :func:`~lowerbase.legged_driver.node.import_ros`, with ``rospy`` the stand-in
    (:class:`~lowerbase.ros2.wire.RclpyShim`) and the ROS 2 types under their ROS 1 names."""
    from geometry_msgs.msg import Twist
    from lowerbase_legged_msgs import msg, srv
    from sensor_msgs.msg import Joy
    from std_srvs.srv import Trigger  # type: ignore[import-untyped]

    ros1_names()
    return SimpleNamespace(rospy=rospy, Twist=Twist, Joy=Joy, Trigger=Trigger,
                           TriggerResponse=Trigger.Response, msg=msg, srv=srv)


class AnyStampIo:
    """A message-builder module (``lowerbase.world.ros_msgs``, ``lowerbase.navigation.
    ros_msgs``) whose functions get a ``builtin_interfaces/Time`` wherever the face passes a
    :class:`~lowerbase.ros2.wire.Stamp` (any argument); everything else passes unchanged."""

    def __init__(self, io: ModuleType) -> None:
        self._io = io

    def __getattr__(self, name: str) -> Any:
        from lowerbase.ros2.wire import Stamp

        value = getattr(self._io, name)
        if not callable(value) or isinstance(value, type):
            return value

        def stamped(*args: Any, **kwargs: Any) -> Any:
            args = tuple(a.to_msg() if isinstance(a, Stamp) else a for a in args)
            kwargs = {k: v.to_msg() if isinstance(v, Stamp) else v for k, v in kwargs.items()}
            return value(*args, **kwargs)
        stamped.__name__ = name
        setattr(self, name, stamped)  # built once per name
        return stamped
