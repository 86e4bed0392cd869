"""``python -m benchmarks [--quick] [--only NAME ...] [--write docs/benchmarks.md]``."""

from __future__ import annotations

import argparse
import importlib
import platform
import sys
import time
from pathlib import Path

from benchmarks.common import Row

MODULES = ("bench_protocol", "bench_emulator", "bench_fleet", "bench_bus", "bench_bms",
           "bench_bms_modbus",
           "bench_driver", "bench_scenarios", "bench_world", "bench_localization",
           "bench_recording", "bench_world_loop", "bench_navigation", "bench_shift",
           "bench_legged", "bench_trace", "bench_robot_sim", "bench_campaign", "bench_ros2",
           "bench_ros2_robot")


def _fmt(v: float) -> str:
    if v != v:  # NaN
        return "n/a"
    if abs(v) >= 1000:
        return f"{v:,.0f}"
    return f"{v:.3g}" if abs(v) < 10 else f"{v:.1f}"


def table(rows: list[Row]) -> str:
    lines = ["| group | benchmark | value | unit | note |", "|---|---|---|---|---|"]
    lines += [f"| {r.group} | {r.name} | {_fmt(r.value)} | {r.unit} | {r.note} |" for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument("--quick", action="store_true", help="shorter runs (smoke test)")
    parser.add_argument("--only", nargs="+", choices=MODULES, help="run only these modules")
    parser.add_argument("--write", metavar="FILE", help="write the results table into FILE")
    args = parser.parse_args(argv)
    rows: list[Row] = []
    for name in args.only or MODULES:
        try:
            module = importlib.import_module(f"benchmarks.{name}")
        except ModuleNotFoundError as exc:
            print(f"# {name}: skipped ({exc})", file=sys.stderr)
            continue
        t0 = time.perf_counter()
        got = module.run(quick=args.quick)
        rows += got
        print(f"# {name}: {len(got)} rows in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    text = table(rows)
    print(text)
    if args.write:
        machine = (f"{platform.machine()}, {platform.python_implementation()} "
                   f"{platform.python_version()}, {platform.system()} {platform.release()}")
        path = Path(args.write)
        head = path.read_text(encoding="utf-8").split("<!-- results -->")[0] if path.exists() \
            else "# Benchmarks\n\n"
        path.write_text(
            head + "<!-- results -->\n\n"
            f"Measured {time.strftime('%Y-%m-%d')} on {machine} "
            f"({'quick' if args.quick else 'full'} run):\n\n" + text + "\n",
            encoding="utf-8")
        print(f"# wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
