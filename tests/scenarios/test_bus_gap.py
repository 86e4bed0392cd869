"""The full-bus benchmark's attribution of the longest /odom gap (benchmarks/bench_bus.py,
benchmarks.busload_proc): which updates bound it, when their frames arrived, and what the
sending process did (ran, waited on the run queue) in between."""

from __future__ import annotations

import itertools
import math
import os

import can
import pytest

from benchmarks.bench_bus import RunQueueSampler, usage_between
from benchmarks.busload_proc import handle_frame, longest_gap, run_queue_wait
from lowerbase.driver.core import LinkState
from tests.driver.test_receive_stamps import StallingLoop

WALL0 = 1.7e9  #: [s] the wall clock (kernel receive stamps) at the simulated clock's zero


class BenchReaderLoop(StallingLoop):
    """StallingLoop whose reader is the bench driver's: each queued frame a can.Message with
    its kernel receive stamp, handed over by busload_proc.handle_frame; then heard up to now."""

    def step(self) -> None:
        self.queue_frames()
        if self.clock.now() % 1.0 >= self.stall:
            for stamp, frame_id, data in self.backlog:
                msg = can.Message(arbitration_id=frame_id, data=data, is_extended_id=False,
                                  timestamp=WALL0 + stamp)
                handle_frame(self.driver, msg, WALL0 + self.clock.now())
            self.backlog.clear()
            self.driver.heard_until = self.clock.now()
        self.driver.tick()
        self.clock.advance(self.mcu.dt)


def test_the_longest_gap_names_its_updates_and_their_frames_arrival() -> None:
    times = [10.00, 10.02, 10.04, 10.12, 10.14, 10.22]
    stamps = [500.0, 500.1, 500.2, 500.3, 500.4, 500.5]
    gap, start, rx = longest_gap(times, stamps)
    assert math.isclose(gap, 0.08) and start == 10.04  # the first of the two 80 ms gaps
    assert rx == (500.2, 500.3)


def test_no_gap_from_fewer_than_two_updates() -> None:
    for times in ([], [1.0]):
        gap, start, rx = longest_gap(times, times)
        assert math.isnan(gap) and math.isnan(start) and all(math.isnan(t) for t in rx)


def test_usage_between_the_samples_around_the_gap() -> None:
    samples = [(1.0, 100, 1_000), (2.0, 300, 5_000), (3.0, 600, 9_000), (4.0, 700, 30_000)]
    # the last sample at or before 2.5 (t=2) to the first at or after 3.5 (t=4)
    assert usage_between(samples, 2.5, 3.5) == (400e-9, 25_000e-9, 2.0)
    assert usage_between(samples, 2.0, 3.0) == (300e-9, 4_000e-9, 1.0)  # exact hits count
    for t0, t1 in ((0.5, 2.0), (2.0, 4.5)):  # not covered
        assert all(math.isnan(v) for v in usage_between(samples, t0, t1))


def test_the_sampler_reads_a_live_process_schedstat() -> None:
    sampler = RunQueueSampler(os.getpid(), period=0.001)
    try:
        for _ in range(1_000_000):  # wait for samples without a sleep
            if len(sampler.samples) >= 3:
                break
            sum(range(1_000))
    finally:
        sampler.stop()
    assert len(sampler.samples) >= 3
    times = [s[0] for s in sampler.samples]
    assert times == sorted(times)
    assert all(b[1] >= a[1] and b[2] >= a[2] for a, b in itertools.pairwise(sampler.samples))
    assert run_queue_wait() >= 0.0


def test_the_bench_driver_stamps_a_backlog_as_the_node_does() -> None:
    """The bench's driver core, starved 0.3 s every second (a loaded host), keeps every wheel
    count as the node does (tests/driver/test_receive_stamps.py): no re-baseline, /odom_raw's
    distance the emulator's. Handed over unstamped (before), each stall re-baselined."""
    loop = BenchReaderLoop(stamped=True, stall=0.3)
    assert loop.run_until(lambda lp: lp.driver.state == LinkState.READY, timeout=5.0)
    odo = loop.driver.odometry
    assert odo is not None
    x0, true0 = odo.x, loop.mcu.truth.x
    before = loop.driver.stats["odometry_rebaselined"]
    loop.drive(0.5, 0.0, 6.0)
    loop.run(1.0)
    assert loop.driver.stats["odometry_rebaselined"] == before
    assert odo.x - x0 == pytest.approx(loop.mcu.truth.x - true0, abs=0.02)
