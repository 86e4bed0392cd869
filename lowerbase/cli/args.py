"""Shared argparse types, so every subcommand refuses the same bad values the same way."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from lowerbase.files import output_dir, output_file


def positive_seconds(text: str) -> float:
    """A finite number of seconds > 0 (``--duration``); argparse prints the error."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a number of seconds > 0")
    return value


def _whole_number(least: int, why: str) -> Callable[[str], int]:
    """An argparse type: a whole number >= ``least``; below it, ``why`` is the error."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"{text!r}: {why}")
        return value

    return parse


#: a whole number >= 1 (``--workers``)
positive_int = _whole_number(1, "must be 1 or more")
#: a random seed, a whole number >= 0 as numpy's generators take (``--seed``)
seed = _whole_number(0, "a seed is 0 or more")


def check_outputs(args: argparse.Namespace, out: Path) -> None:
    """The report folder ``out`` (``--out``, or a command's default folder) and the files
    ``--record``/``--mcap`` name, where the command has them: writable, or one line before
    the run starts (:mod:`lowerbase.files`)."""
    output_dir(out, "--out" if getattr(args, "out", None) else None)
    for value, flag in ((getattr(args, "record", None), "--record"),
                        (getattr(args, "mcap", None), "--mcap")):
        if isinstance(value, str):  # --no-mcap is False
            output_file(value, flag)
