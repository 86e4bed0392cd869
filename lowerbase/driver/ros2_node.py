"""``lowerbase driver --ros2``: driver_base on ROS 2, the same :class:`DriverNode` as on ROS 1.

The node, its core and its message builders are ROS 1's (:mod:`lowerbase.driver.node`,
:mod:`lowerbase.driver.ros_io`); what is ROS 2 here is how it reaches ROS
(:class:`lowerbase.ros2.wire.Ros2Wire`: QoS per topic, TF as tf2_msgs/TFMessage, /tf_static
transient local), its time stamps (:class:`~lowerbase.ros2.wire.Stamp`) and where its
parameters come from: ROS 2 parameters of the node, declared with the defaults of
``lowerbase/driver/config/driver_base.yaml``, nested keys dotted (``topics.odom``,
``odometry_noise.scale_error``). ROS 1 style arguments are translated: ``_publish_tf:=false``
is ``-p publish_tf:=false``, ``_topics/odom:=/o`` is ``-p topics.odom:=/o``, ``__name:=x`` and
``__ns:=/x`` rename and move the node, any other ``a:=b`` is a remapping. An rclpy executor
thread serves the subscriptions and services; the main thread runs the node's tick loop on
wall time, or with ``use_sim_time`` true (``_use_sim_time:=true``) on /clock's time
(:class:`lowerbase.driver.ros2_time.Ros2Clock`, as :mod:`lowerbase.driver.rostime` on ROS 1),
after waiting for the first /clock.

Nothing binds beyond loopback unless the environment says otherwise
(:func:`loopback_only`: a Fast DDS profile with UDP on 127.0.0.1 only, because under
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` alone Fast DDS still binds every interface).
rclpy is imported only in :mod:`lowerbase.ros2`.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Mapping, MutableMapping, Sequence
from pathlib import Path
from typing import Any

from lowerbase.errors import RosUnavailableError
from lowerbase.ros2 import FASTDDS_LOOPBACK

NODE_NAME = "driver_base"
DEFAULTS = Path(__file__).resolve().parent / "config" / "driver_base.yaml"
#: parameters every rclpy node has; not the driver's
#: the Fast DDS profile that keeps a process on loopback (:func:`loopback_only`)
LOOPBACK_PROFILE = FASTDDS_LOOPBACK
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")  # rclpy's own


def import_rclpy() -> Any:
    """rclpy (and the ROS 2 message packages the driver needs), or one line saying how."""
    try:
        import rclpy
        import std_srvs.srv  # type: ignore[import-untyped]  # noqa: F401
        import tf2_msgs.msg  # noqa: F401

        from lowerbase.driver import ros_io  # noqa: F401 (woosh_msgs and the std messages)
    except ImportError as exc:
        raise RosUnavailableError(
            f"ROS 2 is not importable from {sys.executable} ({exc}): run make ros2 and use "
            ".venv-ros2/bin/lowerbase (docs/ros2.md)") from None
    from rclpy.type_support import check_for_type_support
    from tf2_msgs.msg import TFMessage
    from woosh_msgs.msg import Battery

    try:  # the built packages' C libraries, found through LD_LIBRARY_PATH
        for cls in (Battery, TFMessage):
            check_for_type_support(cls)
    except Exception as exc:  # rosidl's UnsupportedTypeSupport
        raise RosUnavailableError(
            f"{exc}: run eval \"$(.venv-ros2/bin/lowerbase ros2-env)\" in this shell first "
            "(docs/ros2.md)") from None
    return rclpy


def loopback_only(environ: MutableMapping[str, str]) -> bool:
    """Keep this process' DDS on 127.0.0.1 unless the environment asks for more: with the
    discovery range LOCALHOST (or unset) and no Fast DDS profile of the user's, use
    :data:`LOOPBACK_PROFILE` (UDP bound to 127.0.0.1 only, and shared memory) instead of the
    range, under which Fast DDS still binds sockets on every interface. True if it did."""
    scope = environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST") or "LOCALHOST"
    if scope != "LOCALHOST" or environ.get("ROS_LOCALHOST_ONLY", "1") not in ("1", ""):
        return False
    if environ.get("FASTDDS_DEFAULT_PROFILES_FILE") or \
            environ.get("FASTRTPS_DEFAULT_PROFILES_FILE"):
        environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        return False
    environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(LOOPBACK_PROFILE)
    environ.pop("ROS_LOCALHOST_ONLY", None)
    environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SYSTEM_DEFAULT"  # the profile limits it
    return True


def ros2_arguments(ros_args: Sequence[str]) -> list[str]:
    """ROS 1 style ``NAME:=VALUE`` arguments as rclpy's ``--ros-args`` list."""
    out: list[str] = []
    for arg in ros_args:
        name, _, value = arg.partition(":=")
        if name == "__name":
            out += ["-r", f"__node:={value}"]
        elif name == "__ns":
            out += ["-r", f"__ns:={value}"]
        elif name.startswith("__"):
            continue  # __log, __master, ...: ROS 1's business
        elif name.startswith("_"):
            out += ["-p", f"{name[1:].replace('/', '.')}:={value}"]
        else:
            out += ["-r", arg]
    return out


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"topics": {"odom": "/odom"}}`` -> ``{"topics.odom": "/odom"}`` (empty dicts go)."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, Mapping):
            flat.update(flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def unflatten(flat: Mapping[str, Any]) -> dict[str, Any]:
    tree: dict[str, Any] = {}
    for name, value in flat.items():
        *parents, leaf = name.split(".")
        node = tree
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return tree


def node_parameters(node: Any) -> dict[str, Any]:
    """The driver's private parameters (a nested dict, as ``rospy.get_param("~")``): the
    defaults declared as ROS 2 parameters, what was given on the command line over them."""
    import yaml

    defaults = flatten(yaml.safe_load(DEFAULTS.read_text()) or {})
    for name, value in defaults.items():
        if not node.has_parameter(name):
            node.declare_parameter(name, value)
    given = {name: p.value for name, p in node.get_parameters_by_prefix("").items()
             if name not in RCLPY_PARAMETERS and not name.startswith("qos_overrides.")}
    return unflatten(given)


@contextlib.contextmanager
def _signals_to(stop: Callable[[str], None]) -> Iterator[None]:
    """SIGINT and SIGTERM end the loop (not rclpy's handlers, which would shut the context
    down under the node before it has sent its last stop)."""
    def handle(signum: int, _frame: Any) -> None:
        stop(signal.Signals(signum).name)

    old = {s: signal.signal(s, handle) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def start_node(name: str, ros_args: Sequence[str], **node_options: Any) -> tuple[Any, Any]:
    """(context, node): rclpy initialised in a context of its own on loopback (Fast DDS
    profile), with the ROS 1-style ``ros_args`` translated, without rclpy's signal handlers
    (the caller's own stop the process); stdout line-buffered for the stop line; lowerbase's
    log records on the node's logger (console and /rosout, :mod:`lowerbase.ros2.logs`)."""
    rclpy = import_rclpy()
    loopback_only(os.environ)
    from rclpy.signals import SignalHandlerOptions

    with contextlib.suppress(AttributeError, ValueError):
        sys.stdout.reconfigure(line_buffering=True)  # type: ignore[union-attr]
    context = rclpy.Context()
    rclpy.init(args=["lowerbase", "--ros-args", *ros2_arguments(ros_args)], context=context,
               signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name, context=context, **node_options)
    from lowerbase.ros2.logs import to_rosout

    to_rosout(node)  # for the process' life: lowerbase's records on its console and /rosout
    return context, node


def run(
    link_factory: Callable[[Callable[[], None]], Any], ros_args: Sequence[str],
    *, name: str = NODE_NAME, params: dict[str, Any] | None = None,
) -> int:
    """:func:`lowerbase.driver.node.run` on ROS 2."""
    rclpy = import_rclpy()
    from rclpy.executors import SingleThreadedExecutor

    from lowerbase.driver import ros_io
    from lowerbase.driver.node import DriverNode
    from lowerbase.driver.ros2_time import Ros2Clock
    from lowerbase.driver.settings import load_settings
    from lowerbase.ros2.wire import RclpyShim, Ros2Wire, StampedIo, uses_sim_time

    context, node = start_node(name, ros_args,
                               automatically_declare_parameters_from_overrides=True)
    shim = RclpyShim(node)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    driver: DriverNode | None = None
    link: Any = None
    spinner: threading.Thread | None = None
    try:
        settings, config = load_settings({**node_parameters(node), **(params or {})})

        def finished() -> None:
            print("lowerbase driver: replay finished", file=sys.stderr, flush=True)
            shim.signal_shutdown("replay finished")

        def serve() -> None:
            while not shim.is_shutdown():
                executor.spin_once(timeout_sec=0.1)

        clock: Ros2Clock | None = None
        if uses_sim_time(node):  # the core and the loop on /clock's time
            clock = Ros2Clock(node, shim)
            shim.Time.source = clock.now
        spinner = threading.Thread(target=serve, name="driver_base-rclpy", daemon=True)
        spinner.start()
        if clock is not None:
            print("lowerbase driver: use_sim_time is true: waiting for /clock", flush=True)
            with _signals_to(shim.signal_shutdown):
                if not clock.wait_for_first():
                    return 0
        link = link_factory(finished)
        driver = DriverNode(settings, config, link, clock=clock, wire=Ros2Wire(node),
                            ros=(shim, StampedIo(ros_io)))
        if clock is not None:  # frames handled late lag /clock K x as much (K x real time)
            driver.core.allow_receive_lag(config.link_timeout)
        driver.advertise()
        driver.start_reader()
        scope = "loopback only" if os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE") == \
            str(LOOPBACK_PROFILE) else \
            os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "SYSTEM_DEFAULT"
        print(f"lowerbase driver: {shim.get_name()} on ROS 2 (domain "
              f"{context.get_domain_id()}, discovery {scope}); link {link.description}",
              flush=True)
        with _signals_to(shim.signal_shutdown):
            driver.spin()
    finally:
        shim.signal_shutdown("driver stopped")
        if driver is not None:
            driver.shutdown()
            counts = ", ".join(f"{k} {v}" for k, v in sorted(driver.core.stats.items()))
            print(f"lowerbase driver: stopped; {counts or 'nothing counted'}",
                  file=sys.stderr, flush=True)
        elif link is not None:
            link.close()
        if spinner is not None:
            spinner.join(timeout=3.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return 0
