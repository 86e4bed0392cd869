"""``lowerbase emulate``: run the emulated lower computer on any transport."""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import sys
import threading
from typing import Any

from lowerbase.cli.args import positive_seconds
from lowerbase.cli.world import add_world_arguments
from lowerbase.files import output_file

log = logging.getLogger("lowerbase.emulate")

#: where --truth-udp sends without a value (lowerbase.world.truth_stream's default)
_TRUTH_UDP_DEFAULT = "127.0.0.1:43213"
#: where --foxglove listens without a value (lowerbase.recording.live's default)
_FOXGLOVE_DEFAULT = "127.0.0.1:8765"


def add_subparser(subparsers: Any) -> None:
    from lowerbase.firmware_model.faults import DEFECTS
    from lowerbase.transport import add_bus_arguments

    p = subparsers.add_parser(
        "emulate",
        help="run the emulated lower computer (chassis MCU)",
        description="Run the emulated chassis MCU. With no bus option it listens on "
        "udp_multicast 239.74.163.2:43113 (hop limit 0: this host only); take python-can's "
        "flags for any CAN interface (e.g. -i socketcan -c vcan0), --serial for the serial "
        "framing, or --slcan to appear as a USB-CAN adapter on a pseudo-terminal.",
        epilog="Faults: stall:left|right, overcurrent:left|right, encoder:left|right, "
        "imu-freeze, imu-bias:RAD_S, silence, drop:P, delay:S, corrupt:P, estop, bms-silence; "
        "add @T to start T s after boot and +D to last D s (e.g. --fault stall:left@5+2). "
        "Deliberate firmware bugs, to test a conformance suite: "
        + ", ".join(f"defect:{name}" for name in DEFECTS) + ".",
    )
    add_bus_arguments(p)
    p.add_argument("--robot", choices=("wheeled", "legged"), default="wheeled",
                   help="wheeled: the differential-drive chassis (default); legged: the "
                   "quadruped's lower computer on four leg buses (udp_multicast ports "
                   "PORT..PORT+3, virtual CHANNEL/0..3, else -c can0,can1,can2,can3; "
                   "docs/legged.md)")
    p.add_argument("--slcan", metavar="PORT",
                   help="act as an slcan USB-CAN adapter on PORT (pty:LINK creates a pty)")
    p.add_argument("--profile", metavar="FILE", help="robot profile TOML (default: packaged)")
    p.add_argument("--params", metavar="FILE",
                   help="parameter file, written atomically on every parameter write")
    p.add_argument("--fault", action="append", default=[], metavar="SPEC",
                   help="inject a fault (repeatable); see below")
    p.add_argument("--fleet", type=_chassis_count, metavar="N",
                   help="run N lower computers in this process on one clock, chassis k on its "
                   "own bus: udp_multicast port PORT+k (default 43113+k), same group")
    p.add_argument("--duration", type=positive_seconds, metavar="S", help="stop after S seconds")
    timing = p.add_mutually_exclusive_group()
    timing.add_argument("--realtime", dest="simulated", action="store_false",
                        help="run in real time (default)")
    timing.add_argument("--simulated", dest="simulated", action="store_true",
                        help="simulated clock, as fast as the CPU allows (needs --duration)")
    p.add_argument("--speed", type=_speed_factor, default=1.0, metavar="K",
                   help="real-time mode K times as fast as the wall clock (K > 0, default 1): "
                   "the control loop, the frames' cycles, --duration, the fault times and the "
                   "truth stream's t and 50 Hz all run on this sped-up time (lowerbase robot "
                   "--sim-time)")
    bms = p.add_argument_group("battery and BMS")
    bms.add_argument("--no-bms", action="store_true", help="run without a BMS")
    bms.add_argument("--soc", type=float, default=80.0, metavar="PERCENT",
                     help="initial state of charge of the own pack (default 80)")
    bms.add_argument("--charger", action="store_true", help="start with the charger connected")
    bms.add_argument("--bms-tcp", metavar="HOST:PORT",
                     help="serve the own BMS over Modbus TCP (with --bms-external: poll this "
                     "external BMS instead)")
    bms.add_argument("--bms-rtu", metavar="PORT",
                     help="serve the own BMS over Modbus RTU on PORT or pty:LINK (with "
                     "--bms-external: poll the BMS on this serial port)")
    bms.add_argument("--bms-unit", type=int, default=1, help="Modbus unit id (default 1)")
    bms.add_argument("--bms-external", action="store_true",
                     help="poll an external BMS (lowerbase bms, or a real one) over "
                     "--bms-tcp or --bms-rtu instead of simulating a pack")
    p.add_argument("--print", dest="print_frames", action="store_true",
                   help="print every frame sent, decoded")
    p.add_argument("--truth", metavar="FILE",
                   help="write the ground truth (t,x,y,yaw,v,w) as CSV every 20 ms")
    p.add_argument("--truth-udp", nargs="?", const=_TRUTH_UDP_DEFAULT, metavar="[HOST:]PORT",
                   help="stream the ground truth (t,x,y,yaw,v,w,contact) at 50 Hz as UDP "
                   "datagrams to HOST:PORT, for lowerbase world (default "
                   f"{_TRUTH_UDP_DEFAULT}; HOST defaults to 127.0.0.1)")
    p.add_argument("--foxglove", nargs="?", const=_FOXGLOVE_DEFAULT, metavar="HOST:PORT",
                   help="live view: serve the ground truth and every frame (raw and decoded) "
                   f"to Foxglove over WebSocket (default {_FOXGLOVE_DEFAULT}; "
                   "docs/recording.md)")
    world = p.add_argument_group(
        "world (contact)", "with --map the robot stops at walls and obstacles; give lowerbase "
        "world the same --map/--obstacles/--place")
    add_world_arguments(world, None)
    p.set_defaults(func=run, simulated=False)


def run(args: argparse.Namespace) -> int:
    import can

    from lowerbase.errors import ConfigError
    from lowerbase.firmware_model.faults import parse_fault
    from lowerbase.firmware_model.mcu import Mcu
    from lowerbase.firmware_model.profile import load_profile
    from lowerbase.firmware_model.runner import bus_sender
    from lowerbase.firmware_model.runner import run as run_mcu
    from lowerbase.protocol.codec import default_codec
    from lowerbase.transport import config_from_args, describe, open_bus
    from lowerbase.transport.peers import PeerMonitor

    if getattr(args, "robot", "wheeled") == "legged":
        from lowerbase.legged.emulate import run_legged

        if getattr(args, "speed", 1.0) != 1.0:
            raise ConfigError("--speed is for the wheeled robot; drop it with --robot legged")

        _compile_notice("legged")
        return run_legged(args)
    if args.simulated and args.duration is None:
        raise ConfigError("--simulated needs --duration (it runs as fast as the CPU allows)")
    if args.simulated and getattr(args, "speed", 1.0) != 1.0:
        raise ConfigError("--speed K paces real time K times faster; --simulated already runs "
                          "as fast as the CPU allows: drop one of them")
    if args.truth:
        output_file(args.truth, "--truth")
    if args.truth_udp is not None:  # a bad address is refused before anything starts
        from lowerbase.world.truth_stream import parse_address

        parse_address(args.truth_udp)
    if args.foxglove is not None and args.fleet is None:
        from lowerbase.recording.live import parse_address as parse_foxglove

        parse_foxglove(args.foxglove)
    if args.map is None and (args.obstacles or args.initial_pose or args.place):
        raise ConfigError("--obstacles, --initial-pose and --place go with --map NAME|FILE")
    profile = load_profile(args.profile)
    faults = [parse_fault(spec) for spec in args.fault]
    if args.simulated:
        _compile_notice()
    if args.fleet is not None:
        return _run_fleet(args, profile, faults)
    if args.slcan:
        config: dict[str, Any] = {"interface": "slcan_device", "channel": args.slcan}
    else:
        config = config_from_args(args)
    if not 0 <= args.soc <= 100:
        raise ConfigError("--soc must be within 0..100 %")
    bms = None if args.no_bms else _make_bms(profile, args)
    try:
        bus = open_bus(config)
    except BaseException:
        if bms is not None:
            bms.close()
        raise
    stop = threading.Event()
    clock = make_clock(args, stop)
    feed = None
    try:
        if args.foxglove is not None:
            from lowerbase.recording.live import EmulatorFeed, start_live

            live = start_live(args.foxglove, name="lowerbase emulate",
                              announce=lambda line: print(f"lowerbase emulate: {line}",
                                                          flush=True))
            feed = EmulatorFeed([live], clock)
        codec = default_codec()
        # warns once when another lower computer (emulator or firmware) shares this bus
        peers = PeerMonitor(codec)
        # transmit errors (a bus-off adapter, a full socket buffer) are counted in mcu.stats
        send = bus_sender(bus, lambda key: mcu.stats.update([key]),
                          on_sent=lambda fid, data: peers.on_sent(fid, data, clock.now()))
        if args.print_frames:
            inner = send

            def send(frame_id: int, data: bytes) -> None:
                inner(frame_id, data)
                name, values = codec.decode(frame_id, data, decode_choices=True, strict=False)
                print(f"{clock.now():10.3f} {name:<18} {values}", flush=True)

        if feed is not None:
            send = _fed(send, feed)
        mcu = Mcu(profile, clock, send, params_path=args.params, bms=bms, faults=faults)
        if feed is not None:
            feed.bind(mcu)
            mcu.receive = _fed(mcu.receive, feed, "rx")  # type: ignore[method-assign]
        # before the ready line: contact (and the charger's) from the first step
        charger = _install_world(mcu, args) if args.map is not None else None
        hooks = _truth_hooks(args) + [h for h in (feed, charger) if h is not None]

        def _stop(*_: Any) -> None:
            stop.set()

        # Ctrl-C and SIGTERM end the loop at a period boundary, whatever runs at that moment
        # (a KeyboardInterrupt in the middle of start-up or of a hook left no clean exit)
        signal.signal(signal.SIGTERM, _stop)
        signal.signal(signal.SIGINT, _stop)
        where = getattr(bus, "stream", None)
        target = where.name if where is not None else describe(config)
        print(f"lowerbase emulate: lower computer on {target} "
              f"({_timing(args)}, boot #{mcu.boot_counter}"
              f"{', faults: ' + ', '.join(map(str, faults)) if faults else ''}); Ctrl-C stops",
              flush=True)
        periodic = [m for m in codec if m.is_periodic and "Lower" in m.senders
                    and (bms is not None or not m.name.startswith("Bms"))]
        print("sending " + ", ".join(f"{m.name} {(m.cycle_time or 0) * 1000:g} ms"
                                     for m in periodic)
              + "; answering ParameterRequest, VersionRequest"
              + ("" if args.print_frames else " (--print shows every frame)"), flush=True)

        with contextlib.suppress(KeyboardInterrupt):
            run_mcu(mcu, bus, clock, duration=args.duration, stop=stop,
                    on_step=_chain(hooks), peers=peers)
        for hook in hooks:
            hook.close()
        feed = None
        mcu.shutdown()
        stats = ", ".join(f"{k} {v}" for k, v in sorted(mcu.stats.items()))
        slips = getattr(clock, "summary", lambda: "")()
        print(f"lowerbase emulate: stopped after {clock.now() - mcu.boot_time:.1f} s; {stats}"
              f"{'; ' + slips if slips else ''}", file=sys.stderr)
    finally:
        if feed is not None:
            feed.close()
        if bms is not None:
            bms.close()
        with contextlib.suppress(can.CanError):
            bus.shutdown()
    return 0


def compile_notice(robot: str = "wheeled") -> str | None:
    """The line that says the ``robot``'s kernels compile in this run (not cached yet), or
    None. On the simulated clock the compile counts against the run's factor (about 14 s of
    CPU once for the chassis; docs/benchmarks.md, "CLI emulate"); in real time the emulator
    starts serving its buses after it."""
    from lowerbase.jit import CHASSIS_KERNEL_MODULES, LEGGED_KERNEL_MODULES, uncached

    legged = robot == "legged"
    if not uncached(LEGGED_KERNEL_MODULES if legged else CHASSIS_KERNEL_MODULES):
        return None
    whose = "the legged robot's" if legged else "the chassis'"
    return (f"lowerbase emulate: compiling {whose} numba kernels first (not cached yet: once, "
            f"seconds to minutes; `lowerbase warm` does it ahead)")


def _compile_notice(robot: str = "wheeled") -> None:
    line = compile_notice(robot)
    if line is not None:
        print(line, file=sys.stderr, flush=True)


def _fed(inner: Any, feed: Any, direction: str = "tx") -> Any:
    """``inner(frame_id, data)`` that also hands the frame to the live view (--foxglove)."""

    def each(frame_id: int, data: bytes) -> None:
        inner(frame_id, data)
        feed.frame(direction, frame_id, data)

    return each


class _SinceBoot:
    """Surroundings asked in time since the first boot (the truth stream's and the world's
    obstacle clock), whatever clock the MCU runs on."""

    def __init__(self, inner: Any, t0: float) -> None:
        self.inner, self.t0 = inner, t0

    def allowed(self, pose_from: Any, pose_to: Any, t: float) -> bool:
        return bool(self.inner.allowed(pose_from, pose_to, t - self.t0))


def _install_world(mcu: Any, args: argparse.Namespace) -> Any:
    """--map: the world's contact checker in the emulator's ground truth (the seam
    firmware_model.truth.Surroundings; the firmware model never imports lowerbase.world);
    returns the charger contact's runner hook (lowerbase.world.charger), or None."""
    from lowerbase.cli.world import world_parts
    from lowerbase.world.charger import contact_for
    from lowerbase.world.truth import WorldSurroundings

    parts = world_parts(args)
    mcu.truth.surroundings = _SinceBoot(
        WorldSurroundings(parts.grid, parts.obstacles, map_from_truth=parts.start),
        mcu.boot_time)
    charger = contact_for(mcu, args.map, parts.grid, parts.start,
                          lambda line: print(f"lowerbase emulate: {line}", flush=True))
    print(f"lowerbase emulate: on map {args.map} at {parts.where}: the robot stops at walls "
          f"and obstacles" + ("" if charger is None else ", the BMS charges while it stands "
                              "on the charger"), flush=True)
    return charger


def _truth_hooks(args: argparse.Namespace) -> list[Any]:
    """The runner hooks that publish the ground truth: --truth (CSV), --truth-udp."""
    hooks: list[Any] = []
    if args.truth:
        from lowerbase.simloop.truth import TruthLog

        hooks.append(TruthLog(args.truth))
    if args.truth_udp is not None:
        from lowerbase.world.truth_stream import TruthSender, parse_address

        host, port = parse_address(args.truth_udp)
        hooks.append(TruthSender(host, port))
        print(f"lowerbase emulate: ground truth to udp {host}:{port} at 50 Hz", flush=True)
    return hooks


def _chain(hooks: list[Any]) -> Any:
    if len(hooks) <= 1:
        return hooks[0] if hooks else None

    def each(mcu: Any) -> None:
        for hook in hooks:
            hook(mcu)

    return each


def make_clock(args: argparse.Namespace, stop: threading.Event) -> Any:
    """The emulator's clock: simulated, real time, or real time x ``--speed``."""
    from lowerbase.clock import PacedClock, RealClock, ScaledClock, SimClock

    if args.simulated:
        return SimClock()
    speed = getattr(args, "speed", 1.0)
    wall = RealClock(stop) if speed == 1.0 else ScaledClock(speed, stop)
    # the model's time: it slips (counted, warned of) where the host cannot keep the period
    return PacedClock(wall, name="lowerbase emulate")


def _timing(args: argparse.Namespace) -> str:
    if args.simulated:
        return "simulated time"
    speed = getattr(args, "speed", 1.0)
    return "real time" if speed == 1.0 else f"{speed:g} x real time"


def _speed_factor(text: str) -> float:
    try:
        k = float(text)
    except ValueError:
        k = 0.0
    if not (0 < k < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a number > 0 (2: twice real time), not "
                                         f"{text!r}")
    return k


def _chassis_count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number of chassis >= 1, not {text!r}")
    return n


#: single-chassis options a fleet does not take (each chassis has its own pack, no files)
_NOT_WITH_FLEET = ("serial", "slcan", "params", "bms_tcp", "bms_rtu", "bms_external",
                   "print_frames", "truth", "truth_udp", "map", "foxglove")


def _run_fleet(args: argparse.Namespace, profile: Any, faults: list[Any]) -> int:
    """``--fleet N``: N chassis stepped together by runner.run_fleet, each on its own bus."""
    from lowerbase.errors import ConfigError
    from lowerbase.firmware_model.runner import close_fleet, fleet_bus_configs, open_fleet
    from lowerbase.firmware_model.runner import run_fleet as run_all
    from lowerbase.transport import config_from_args, describe

    given = [name for name in _NOT_WITH_FLEET if getattr(args, name)]
    if given:
        raise ConfigError(f"--fleet runs each chassis with its own pack on its own bus; drop "
                          f"--{given[0].replace('_', '-').replace('print-frames', 'print')}")
    if not 0 <= args.soc <= 100:
        raise ConfigError("--soc must be within 0..100 %")
    config = config_from_args(args)
    configs = fleet_bus_configs(config, args.fleet)  # refuses what cannot host a fleet
    stop = threading.Event()
    clock = make_clock(args, stop)
    fleet = open_fleet(profile, clock, config, args.fleet, bms=not args.no_bms, soc=args.soc,
                       charger=args.charger, faults=faults)
    try:
        first, last = configs[0], configs[-1]
        where = (f"ports {first['port']}..{last['port']} (chassis k on port {first['port']}+k)"
                 if "port" in first else f"channels {first['channel']}..{last['channel']}")
        print(f"lowerbase emulate: fleet of {args.fleet} lower computers on "
              f"{describe({k: v for k, v in config.items() if k != 'port'})}, {where} "
              f"({_timing(args)}); Ctrl-C stops", flush=True)
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        with contextlib.suppress(KeyboardInterrupt):
            run_all(fleet, clock, duration=args.duration, stop=stop)
        totals: dict[str, int] = {}
        for chassis in fleet:
            for key, value in chassis.mcu.stats.items():
                totals[key] = totals.get(key, 0) + value
        stats = ", ".join(f"{k} {v}" for k, v in sorted(totals.items()))
        print(f"lowerbase emulate: fleet stopped after {clock.now() - fleet[0].mcu.boot_time:.1f}"
              f" s; all {args.fleet} together: {stats}"
              f"{'; ' + slips if (slips := getattr(clock, 'summary', lambda: '')()) else ''}",
              file=sys.stderr)
    finally:
        close_fleet(fleet)
    return 0


def _make_bms(profile: Any, args: argparse.Namespace) -> Any:
    """The BMS the lower computer polls: its own pack (maybe also served), or an external one."""
    from lowerbase.bms.adapter import McuBmsAdapter
    from lowerbase.bms.device import parse_host_port
    from lowerbase.bms.link import ModbusRtuBmsLink, ModbusTcpBmsLink
    from lowerbase.errors import ConfigError

    if args.bms_external:
        if args.bms_tcp:
            host, port = parse_host_port(args.bms_tcp)
            return McuBmsAdapter.external(ModbusTcpBmsLink(host, port, unit=args.bms_unit),
                                          profile)
        if args.bms_rtu:
            return McuBmsAdapter.external(ModbusRtuBmsLink(args.bms_rtu, unit=args.bms_unit),
                                          profile)
        raise ConfigError("--bms-external needs --bms-tcp HOST:PORT or --bms-rtu PORT")
    adapter = McuBmsAdapter.from_profile(profile, soc=args.soc, charger=args.charger,
                                         unit=args.bms_unit)
    if args.bms_tcp or args.bms_rtu:
        tcp = parse_host_port(args.bms_tcp) if args.bms_tcp else None
        server = adapter.serve(tcp=tcp, rtu=args.bms_rtu)
        where = [f"Modbus TCP {server.tcp_address[0]}:{server.tcp_address[1]}"
                 if server.tcp_address else "", f"Modbus RTU {args.bms_rtu}" if args.bms_rtu
                 else ""]
        print(f"lowerbase emulate: BMS (unit {args.bms_unit}) on "
              f"{' and '.join(w for w in where if w)}", flush=True)
    return adapter
