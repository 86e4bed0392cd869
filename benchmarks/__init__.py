"""Benchmarks: ``python -m benchmarks [--quick] [--only NAME] [--write docs/benchmarks.md]``.

Each module has ``run(quick: bool) -> list[Row]``; rows are printed as one table. Numbers are
measured, never asserted: tests stay deterministic, speed lives here.
"""
