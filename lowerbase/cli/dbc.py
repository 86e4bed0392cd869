"""``lowerbase dbc``: show the catalog, or export docs/protocol.md from it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from lowerbase.errors import ConfigError
from lowerbase.files import output_file, write_atomic


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "dbc",
        help="show the frame catalog (chassis.dbc) or export docs/protocol.md",
        description="Show the frame catalog, one line a message, or with --signals every "
        "signal; --export-docs writes the protocol document generated from the DBC.",
    )
    p.add_argument("--signals", action="store_true", help="list every signal too")
    p.add_argument("--path", action="store_true", help="print the path of chassis.dbc")
    p.add_argument("--export-docs", metavar="FILE", help="write the protocol document")
    p.add_argument(
        "--check-docs", metavar="FILE", help="exit 1 if FILE differs from the generated document"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from lowerbase.protocol.codec import DBC_PATH, default_codec
    from lowerbase.protocol.docs import render

    if args.path:
        print(DBC_PATH)
        return 0
    if args.export_docs:
        write_atomic(output_file(args.export_docs, "--export-docs"), render())
        print(f"wrote {args.export_docs}")
        return 0
    if args.check_docs:
        path = Path(args.check_docs)
        if not path.exists():
            raise ConfigError(f"{path} does not exist; run lowerbase dbc --export-docs {path}")
        if path.read_text(encoding="utf-8") != render():
            print(f"{path} is out of date; run: lowerbase dbc --export-docs {path}")
            return 1
        print(f"{path} is up to date")
        return 0
    codec = default_codec()
    print(f"{'ID':>6}  {'message':<18} {'DLC':>3}  {'cycle':>8}  sender")
    for m in codec:
        cycle = f"{m.cycle_time * 1000:g} ms" if m.cycle_time else "event"
        print(f"0x{m.frame_id:03X}  {m.name:<18} {m.length:>3}  {cycle:>8}  {','.join(m.senders)}")
        if args.signals:
            for s in m.signals:
                rng = f"[{s.minimum:g} .. {s.maximum:g}]" if s.minimum is not None else ""
                mux = "M" if s.is_multiplexer else ",".join(f"m{k}" for k in s.multiplexer_ids)
                print(f"          {s.name:<17} {mux:<3} {s.start:>2}|{s.length:<2} x{s.scale:g} "
                      f"{rng} {s.unit}".rstrip())
    return 0
