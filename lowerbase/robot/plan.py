"""What ``lowerbase robot`` starts, in order: :func:`robot_plan`.

The parts talk as they would on a robot: the emulated lower computer and driver_base over the
default transport (udp_multicast on loopback, hop limit 0, a port of this run's own, so two
robots on one host never meet); the world reads the emulator's ground truth over UDP on
loopback (``emulate --truth-udp``); the ROS nodes meet on the master. The world starts first
(it must be listening when the emulator starts sending its truth), then the emulator, then
driver_base, then the nodes above it.

With ``sim_speed`` K (``--sim-time``) the emulator runs K x real time and the world publishes
/clock from its ground truth; ``/use_sim_time`` is set on the master before anything starts
(``lowerbase.cli.robot``), so every node's ROS time is the emulator's.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from lowerbase.robot.supervisor import ChildSpec
from lowerbase.transport import free_loopback_port

#: what a lowerbase ROS node prints once it is on the master
ON_MASTER = "on ROS master"
#: the upper layers, bottom to top: (subcommand, extra flags)
UPPER = ("navigation", "tasks")


@dataclass(frozen=True)
class RobotOptions:
    """``map``: a map name or file; ``parts``: the upper layers to start (a subset of
    :data:`UPPER`); ``python``: the interpreter that runs ``-m lowerbase``."""

    map: str
    parts: tuple[str, ...] = UPPER
    bus_port: int | None = None
    truth_port: int | None = None
    python: str = sys.executable
    #: --foxglove HOST:PORT: the recorder child serves the ROS topics and frames live there
    foxglove: str | None = None
    #: --sim-time: the emulator's speed factor K, the world publishes /clock (None: real time)
    sim_speed: float | None = None
    #: --truth FILE: the emulator writes its ground truth there (``emulate --truth``, CSV)
    truth: str | None = None
    #: --mcap FILE: a recorder child writes the ROS topics and the bus's frames there
    mcap: str | None = None
    #: --soc PERCENT: the battery's charge at start (``emulate --soc``; None: its default)
    soc: float | None = None
    #: --ground-truth: the world publishes the true pose as its localization (no amcl)
    ground_truth: bool = False
    #: --respawn: the upper parts are started again when they end (roslaunch's respawn)
    respawn: bool = False


def _lowerbase(opts: RobotOptions, *args: str) -> list[str]:
    return [opts.python, "-m", "lowerbase", *args]


def bus_flags(port: int) -> list[str]:
    from lowerbase.transport import DEFAULT_CHANNEL, DEFAULT_HOP_LIMIT

    return ["-i", "udp_multicast", "-c", DEFAULT_CHANNEL, "--bus-kwargs", f"port={port}",
            f"hop_limit={DEFAULT_HOP_LIMIT}"]


def robot_plan(opts: RobotOptions) -> list[ChildSpec]:
    """The children, in start order, with the text each prints once ready."""
    bus = bus_flags(opts.bus_port or free_loopback_port())
    truth = opts.truth_port or free_loopback_port()
    map_ref = str(Path(opts.map).resolve()) if Path(opts.map).suffix else opts.map
    emulate = ["emulate", *bus, "--truth-udp", f"127.0.0.1:{truth}", "--map", map_ref]
    world = ["world", "--map", map_ref, "--truth-udp", str(truth)]
    if opts.truth:
        emulate += ["--truth", str(Path(opts.truth).resolve())]
    if opts.ground_truth:
        world += ["--ground-truth"]
    if opts.soc is not None:
        emulate += ["--soc", f"{opts.soc:g}"]
    if opts.sim_speed is not None:  # the world is the simulator: /clock from the truth's t
        emulate += ["--speed", f"{opts.sim_speed:g}"]
        world += ["--publish-clock"]
    specs = [ChildSpec("world", _lowerbase(opts, *world), ON_MASTER)]
    if opts.mcap or opts.foxglove:  # before the emulator: every frame (rosrecord)
        specs.append(recorder_spec(opts, bus))
    specs += [
        ChildSpec("emulate", _lowerbase(opts, *emulate), "lower computer on"),
        ChildSpec("driver", _lowerbase(opts, "driver", *bus), "link ready"),
    ]
    for part in UPPER:
        if part in opts.parts:
            specs.append(ChildSpec(part, _lowerbase(opts, part, "--map", map_ref), ON_MASTER,
                                   respawn=opts.respawn))
    return specs


def recorder_spec(opts: RobotOptions, bus: list[str] | None = None) -> ChildSpec:
    """The recorder child of --mcap/--foxglove: the robot's ROS topics, and the frames of
    ``bus`` (None: a bus of its own that nothing sends to, as in lockstep there is no bus)."""
    record = [str(Path(opts.mcap).resolve())] if opts.mcap else []
    if opts.foxglove:
        record += ["--foxglove", opts.foxglove]
    if bus is None:
        bus = bus_flags(opts.bus_port or free_loopback_port())
    return ChildSpec("recorder", [opts.python, "-m", "lowerbase.recording.rosrecord",
                                  *record, *bus], ON_MASTER, essential=False)
