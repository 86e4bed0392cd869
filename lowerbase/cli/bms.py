"""``lowerbase bms``: run the emulated BMS alone, for testing real lower-computer firmware.

Examples::

    lowerbase bms                                  # Modbus TCP on 127.0.0.1:5020, unit 1
    lowerbase bms --tcp 0.0.0.0:502 --unit 3 --idle-timeout 300
    lowerbase bms --rtu /dev/ttyUSB0 --baudrate 9600 --no-tcp
    lowerbase bms --rtu pty:/tmp/lowerbase-bms     # new pseudo-terminal, firmware opens the link
    lowerbase bms --profile robot.toml --soc 30 --charger --speed 60
"""

from __future__ import annotations

import argparse
import signal
import threading
from typing import Any

PTY_PREFIX = "pty:"


def add_subparser(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "bms",
        help="run the emulated BMS alone (Modbus TCP/RTU)",
        description="Serve an emulated battery pack and BMS over Modbus TCP and/or Modbus RTU "
        "so real lower-computer firmware can be tested against it. Register map: "
        "docs/bms-modbus.md. Stop with Ctrl-C or SIGTERM.",
    )
    parser.add_argument(
        "--tcp", metavar="HOST:PORT", default="127.0.0.1:5020",
        help="Modbus TCP listen address (default 127.0.0.1:5020)",
    )
    parser.add_argument("--no-tcp", action="store_true", help="do not serve Modbus TCP")
    parser.add_argument(
        "--rtu", metavar="PORT",
        help="also serve Modbus RTU on a serial device (e.g. /dev/ttyUSB0), or on a new "
        "pseudo-terminal with 'pty:' or 'pty:LINK' (LINK becomes a symlink to the end the "
        "firmware opens, e.g. pty:/tmp/lowerbase-bms)",
    )
    parser.add_argument(
        "--baudrate", type=int, default=19200, help="RTU baud rate (default 19200; 8N1)"
    )
    parser.add_argument("--unit", type=int, default=1, help="Modbus unit id (default 1)")
    parser.add_argument(
        "--idle-timeout", type=float, default=60.0, metavar="SECONDS",
        help="close a Modbus TCP connection that sends nothing for this long "
        "(default 60; 0 = never)",
    )
    parser.add_argument(
        "--profile", metavar="FILE",
        help="TOML file with a [battery] table (default: packaged 16S LFP 40 Ah pack)",
    )
    parser.add_argument(
        "--chemistry", choices=("LFP", "NMC"),
        help="packaged defaults for this chemistry (ignored with --profile)",
    )
    parser.add_argument(
        "--soc", type=float, default=80.0, metavar="PERCENT",
        help="initial state of charge (default 80)",
    )
    parser.add_argument(
        "--charger", choices=("auto", "manual"), nargs="?", const="auto",
        help="start with a charger connected (default mode: auto = docking station)",
    )
    parser.add_argument(
        "--load", type=float, default=0.0, metavar="AMPS",
        help="constant motor load current on top of the idle draw (default 0)",
    )
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument(
        "--realtime", dest="speed", action="store_const", const=1.0,
        help="simulate in real time (the default)",
    )
    speed.add_argument(
        "--speed", type=float, metavar="FACTOR",
        help="simulated seconds per wall-clock second (e.g. 60: one minute per second)",
    )
    parser.set_defaults(func=run, speed=1.0)


def _rtu_port(spec: str) -> tuple[str | None, str | None, bool]:
    """(device path, symlink, is_pty) from the --rtu value."""
    if spec.startswith(PTY_PREFIX):
        link = spec[len(PTY_PREFIX):] or None
        return None, link, True
    return spec, None, False


def run(args: argparse.Namespace) -> int:
    import logging

    from lowerbase.bms.config import default_battery_config, load_battery_config
    from lowerbase.bms.device import BmsDevice, BmsServer, parse_host_port
    from lowerbase.bms.pack import BatteryPack
    from lowerbase.bms.ptybridge import PtyBridge
    from lowerbase.bms.status import ChargeMode
    from lowerbase.clock import RealClock
    from lowerbase.errors import ConfigError

    if not args.debug:
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    if args.speed is None or args.speed <= 0:
        raise ConfigError("--speed must be > 0")
    if not 0 <= args.soc <= 100:
        raise ConfigError("--soc must be within 0-100")
    if args.load < 0:
        raise ConfigError("--load must be >= 0 A")
    if args.idle_timeout < 0:
        raise ConfigError("--idle-timeout must be >= 0 s (0 = never)")
    if args.no_tcp and not args.rtu:
        raise ConfigError("--no-tcp needs --rtu")
    if args.profile:
        config = load_battery_config(args.profile)
    else:
        config = default_battery_config(args.chemistry or "LFP")
    pack = BatteryPack(config, soc=args.soc)
    device = BmsDevice(pack, unit=args.unit)
    device.load_current = args.load
    if args.charger:
        device.connect_charger(ChargeMode.AUTO if args.charger == "auto" else ChargeMode.MANUAL)
    tcp = None if args.no_tcp else parse_host_port(args.tcp)

    bridge: PtyBridge | None = None
    rtu: str | None = None
    if args.rtu:
        path, link, is_pty = _rtu_port(args.rtu)
        if is_pty:
            bridge = PtyBridge(link)
            rtu = bridge.a_path
        else:
            rtu = path
    stop = threading.Event()
    server = BmsServer(
        device, tcp=tcp, rtu=rtu, baudrate=args.baudrate, clock=RealClock(stop),
        speed=args.speed, idle_timeout=args.idle_timeout or None,
    )
    # SIGTERM (systemd, docker, kill) stops as cleanly as Ctrl-C does
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        server.start()
        print(
            f"lowerbase bms: {config.cells_series}S {config.chemistry.value} "
            f"{config.capacity_ah:g} Ah, SOC {args.soc:g} %, unit {args.unit}, "
            f"speed x{args.speed:g}" + (f", charger {args.charger}" if args.charger else ""),
            flush=True,
        )
        if server.tcp_address:
            host, port = server.tcp_address
            print(f"Modbus TCP listening on {host}:{port}", flush=True)
        if bridge is not None:
            where = f"{bridge.link} -> {bridge.b_path}" if bridge.link else bridge.b_path
            print(f"Modbus RTU on pseudo-terminal {where} ({args.baudrate} 8N1)", flush=True)
        elif rtu:
            print(f"Modbus RTU on {rtu} ({args.baudrate} 8N1)", flush=True)
        print("Ctrl-C to stop.", flush=True)
        try:
            stop.wait()
        except KeyboardInterrupt:
            print("stopping", flush=True)
    finally:
        stop.set()
        server.stop()
        if bridge is not None:
            bridge.close()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0
