"""``lowerbase emulate --robot legged``: the legged lower computer on its four leg buses."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading

from lowerbase.errors import ConfigError

#: options of the wheeled emulator that the legged one does not take
NOT_WITH_LEGGED = ("serial", "slcan", "params", "fleet", "bms_tcp", "bms_rtu",
                   "bms_external", "truth", "truth_udp", "map", "foxglove")


def _defects(faults: list[str]) -> tuple[str, ...]:
    """The legged robot takes only ``--fault defect:NAME`` (lowerbase.legged.lower.DEFECTS)."""
    from lowerbase.legged.lower import DEFECTS

    names = []
    for spec in faults:
        kind, _, name = spec.partition(":")
        if kind != "defect" or name not in DEFECTS:
            raise ConfigError(f"--robot legged takes only --fault defect:NAME, NAME one of "
                              f"{', '.join(DEFECTS)} (got {spec!r})")
        names.append(name)
    return tuple(names)


def run_legged(args: argparse.Namespace) -> int:
    """Run the legged lower computer as ``lowerbase emulate`` was asked to."""
    from lowerbase.clock import PacedClock, RealClock, SimClock
    from lowerbase.legged.lower import Send
    from lowerbase.legged.profile import load_legged_profile
    from lowerbase.legged.runner import close_buses, leg_bus_configs, open_legged, run_legged
    from lowerbase.protocol.legged import LEGS, legged_codec
    from lowerbase.transport import config_from_args, describe

    given = [name for name in NOT_WITH_LEGGED if getattr(args, name, None)]
    if given:
        flag = given[0].replace("_", "-")
        raise ConfigError(f"--robot legged does not take --{flag} (four CAN buses, its own "
                          "pack); drop it")
    defects = _defects(getattr(args, "fault", None) or [])
    if args.simulated and args.duration is None:
        raise ConfigError("--simulated needs --duration (it runs as fast as the CPU allows)")
    profile = load_legged_profile(args.profile)
    config = config_from_args(args)
    configs = leg_bus_configs(config)
    stop = threading.Event()
    clock = SimClock() if args.simulated else PacedClock(RealClock(stop),
                                                         name="lowerbase emulate")
    codec = legged_codec()

    def printing(send: Send) -> Send:
        def out(bus: int, frame_id: int, data: bytes) -> None:
            send(bus, frame_id, data)
            try:
                name, values = codec.decode(frame_id, data, decode_choices=True, strict=False)
            except Exception:  # a special frame is no DBC message: shown raw
                name, values = "special", {"data": data.hex(" ")}
            print(f"{clock.now():10.3f} {LEGS[bus]} {name:<20} {values}", flush=True)
        return out

    lower, buses = open_legged(profile, clock, config, bms=not args.no_bms, soc=args.soc,
                               charger=args.charger, defects=defects,
                               wrap_send=printing if args.print_frames else None)
    try:
        if "port" in configs[0]:
            where = (f"ports {configs[0]['port']}..{configs[-1]['port']} (leg bus k = "
                     f"{'/'.join(LEGS)} on port {configs[0]['port']}+k)")
        else:
            where = "channels " + ", ".join(str(c["channel"]) for c in configs)
        drop = "port" if "port" in configs[0] else "channel"
        rest = describe({k: v for k, v in config.items() if k != drop})
        print(f"lowerbase emulate: legged lower computer on {rest}, {where} "
              f"({'simulated' if args.simulated else 'real'} time, profile {profile.source}); "
              "Ctrl-C stops", flush=True)
        print("12 actuators commanded and answering at 1 kHz (3 per leg bus); body frames on "
              f"bus 0 ({LEGS[0]}){'' if args.no_bms else ' with the BMS'}; answering "
              "LocomotionRequest, BodyVelocityCommand", flush=True)
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        with contextlib.suppress(KeyboardInterrupt):
            run_legged(lower, buses, clock, duration=args.duration, stop=stop)
        stats = ", ".join(f"{k} {v}" for k, v in sorted(lower.stats.items()))
        slips = clock.summary() if isinstance(clock, PacedClock) else ""
        print(f"lowerbase emulate: stopped after {clock.now() - lower.boot_time:.1f} s in "
              f"state {lower.body.state.name}; {stats or 'nothing received'}"
              f"{'; ' + slips if slips else ''}", file=sys.stderr)
    finally:
        lower.shutdown()
        close_buses(buses)
    return 0
