"""The world around the emulated chassis on the simulated clock, ROS-free: :class:`WorldSim`.

A :class:`WorldSim` wraps a :class:`~lowerbase.simloop.loop.SimLoop` (emulator + driver) with
a map, its named places, obstacles, the lidar rig (the merged /scan at its rate), the depth
camera (at its rate; off unless asked, it is the costly part), the localizer (amcl, fed with
the driver's /odom pose and the merged scan, or the ground truth) and contact (the footprint
against walls and obstacles, installed in the emulator through the ``Surroundings`` seam, by
a :class:`~lowerbase.world.contact_gate.ContactGate` only while a move may touch something).

Scans are cast lazily, since ray casting is the costly part: at every scan tick (the rig's
rate) the true pose is recorded; the scan itself is cast when the localizer will use it (after
amcl's ``update_min_d`` / ``update_min_a`` of /odom motion, or after a control through
:meth:`WorldSim.initial_pose` / :meth:`WorldSim.start_localization`) or when
:attr:`WorldSim.scan` is read: either way it is the scan of that tick, exactly. The localizer
gets it with /odom at the scan's stamp (:meth:`WorldSim.odom_at`, interpolated between the
/odom samples around it, as amcl's tf lookup does), once /odom has reached that stamp.

:meth:`WorldSim.run_periods` (what :class:`~lowerbase.navigation.sim.NavSim` runs between two
control ticks) hands runs of periods in which the world does nothing to the emulator and driver
at once (:meth:`SimLoop.advance`): up to the next scan tick, while no scan waits for /odom, the
camera is off and the contact gate's free space covers the run; the same bits as stepping
(tests/world/test_world_advance.py).

It reads the robot's truth only through :class:`~lowerbase.world.truth.LoopTruth`; the
emulator's frame is placed on the map at the start pose (``map_from_truth``). What a ROS node
would publish is read off it: :attr:`WorldSim.scan`, :attr:`WorldSim.frame`,
:attr:`WorldSim.estimate` (/amcl_pose), :meth:`WorldSim.amcl_pose` (movebase_pose2d),
:attr:`WorldSim.map_to_odom`, :attr:`WorldSim.contact`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from lowerbase.errors import WorldError
from lowerbase.firmware_model.profile import Profile
from lowerbase.simloop.loop import SimLoop, SteppedLoop
from lowerbase.world.camera import CameraFrame, DepthCamera
from lowerbase.world.contact_gate import ContactGate
from lowerbase.world.footprint import (
    DEFAULT_FOOTPRINT,
    Contact,
    Footprint,
    check_pose,
    validate_pose,
)
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.lidar import Draws, LaserScan, LidarRig
from lowerbase.world.localization import AmclParams, Localizer, PoseEstimate
from lowerbase.world.localization.poses import Pose2D, compose, inverse, wrap_scalar
from lowerbase.world.maps import DEFAULT_MAP, load_map
from lowerbase.world.obstacles import Obstacles
from lowerbase.world.places import Places, load_places
from lowerbase.world.raycast import Scene, Solid
from lowerbase.world.sensors import SensorsConfig, sensors_from_profile_file
from lowerbase.world.truth import ContactEvent, LoopTruth, WorldSurroundings

LOCALIZATION_MODES = ("filter", "truth", "off")


@dataclass(frozen=True)
class WorldConfig:
    """What a WorldSim is made of (all checked before anything is built).

    ``start`` is a pose (x, y, yaw) [m, rad] on the map or a place name of the map's sidecar;
    ``initial_error`` (dx, dy, dyaw) in the robot's frame is how wrong the localizer's initial
    pose is (a user's imprecise /initialpose); ``initial_cov`` its 3x3 covariance (None:
    amcl's default)."""

    map: str | Path | OccupancyGrid = DEFAULT_MAP
    start: Sequence[float] | str = "start"
    obstacles: Obstacles = field(default_factory=Obstacles)
    sensors: SensorsConfig | None = None  #: None: the profile's [sensors]
    localization: str = "filter"  #: filter (amcl), truth (ground truth), off
    initial_error: Sequence[float] = (0.0, 0.0, 0.0)
    initial_cov: Sequence[float] | None = None
    amcl: AmclParams | None = None
    camera: bool = False
    footprint: Footprint = DEFAULT_FOOTPRINT
    seed: int = 0


@dataclass(frozen=True)
class DeferredScan:
    """A scan tick read without casting it (:meth:`WorldSim.skip_scan`): its ``stamp``, the
    true ``pose``, and either its random numbers (``draws``, already taken from the lidars'
    generators) or the ``scan`` itself when it was cast already."""

    stamp: float
    pose: Pose2D
    draws: list[Draws] | None = None
    scan: LaserScan | None = None


def resolve_start(map_ref: str | Path | OccupancyGrid, grid: OccupancyGrid,
                  start: Sequence[float] | str) -> Pose2D:
    """The start as a finite pose: a place name looked up in the map's sidecar."""
    if isinstance(start, str):
        if isinstance(map_ref, OccupancyGrid):
            raise WorldError(f"start {start!r} is a place name, but this map has no places: "
                             "give the start as [x, y, yaw]")
        places: Places = load_places(map_ref, grid)
        return places.pose(start)
    return check_pose(start)


class WorldSim(SteppedLoop):
    """Emulator + driver + world on one simulated clock (see the module docstring)."""

    def __init__(self, config: WorldConfig | None = None, *, loop: SimLoop | None = None,
                 profile: Profile | None = None) -> None:
        cfg = config or WorldConfig()
        if cfg.localization not in LOCALIZATION_MODES:
            raise WorldError(f"localization = {cfg.localization!r} is not known; one of: "
                             f"{', '.join(LOCALIZATION_MODES)}")
        # -- everything checked first: nothing is built or installed on bad input --
        grid = cfg.map if isinstance(cfg.map, OccupancyGrid) else load_map(cfg.map)
        t0 = loop.now if loop is not None else 0.0
        start = validate_pose(resolve_start(cfg.map, grid, cfg.start), grid, cfg.obstacles,
                              t0, cfg.footprint, what="the robot's start pose")
        error = check_pose(cfg.initial_error)
        sensors = cfg.sensors if cfg.sensors is not None else \
            sensors_from_profile_file(footprint=cfg.footprint)
        sensors.check_mounts(cfg.footprint)
        rig = LidarRig(sensors.lidars, sensors.scan)
        camera = DepthCamera(sensors.camera) if cfg.camera and sensors.camera else None
        if cfg.camera and sensors.camera is None:
            raise WorldError("the camera is asked for but the profile's [sensors.camera] is "
                             "disabled")
        self.loop = loop if loop is not None else SimLoop(profile, bms="own")
        self.control_dt = self.loop.mcu.dt
        self.twist_driver = self.loop.driver
        tr = self.loop.mcu.truth
        self.map_from_truth: Pose2D = compose(start, inverse((tr.x, tr.y, tr.yaw)))
        localizer = Localizer(
            grid, cfg.amcl, clock=self.loop.clock, seed=cfg.seed,
            initial_pose=compose(start, error), initial_cov=cfg.initial_cov,
            truth=self.true_pose, ground_truth=cfg.localization == "truth",
            running=cfg.localization != "off")
        # -- built: install the contact seam --
        self.config = cfg
        self.grid = grid
        self.start = start
        #: this world's own copy: the people's waits (what both contact and sensors read)
        self.obstacles = cfg.obstacles.fresh()
        self.sensors = sensors
        self.rig = rig
        self.camera = camera
        self.localizer = localizer
        self.truth = LoopTruth(self.loop)
        self.surroundings = WorldSurroundings(grid, self.obstacles, cfg.footprint,
                                              self.map_from_truth)
        #: installs the surroundings in the emulator only while a move may touch something
        self.gate = ContactGate(self.loop, self.surroundings)
        self.scene = Scene(grid)
        self._tick: tuple[float, Pose2D] | None = None  #: the last scan tick: (t, true pose)
        self._scan: LaserScan | None = None
        self._draws: list[Draws] | None = None  #: the last tick's random numbers, drawn ahead
        self._fed: Pose2D | None = None  #: /odom when the localizer last got a scan
        #: the last two /odom samples (stamp, pose): the scan's odometry is interpolated
        self._odom_hist: list[tuple[float, Pose2D]] = []
        #: a scan tick (t, true pose) the localizer will use once /odom reaches its stamp
        self._pending: tuple[float, Pose2D] | None = None
        self.frame: CameraFrame | None = None  #: the latest camera frame
        self.estimate: PoseEstimate | None = None  #: the latest /amcl_pose
        self.scans = self.frames = 0
        self._scan_period = 1.0 / rig.rate_hz
        self._frame_period = 1.0 / camera.config.rate_hz if camera is not None else math.inf
        self._next_scan = self.loop.now
        self._next_frame = self.loop.now if camera is not None else math.inf

    # -- what the world knows ------------------------------------------------------------------
    @property
    def now(self) -> float:
        return self.loop.now

    def true_pose(self) -> Pose2D:
        """The robot's true pose on the map (the emulator's truth placed at the start)."""
        s = self.truth.sample()
        return compose(self.map_from_truth, (s.x, s.y, s.yaw))

    def odom_pose(self) -> Pose2D | None:
        """The driver's /odom pose, None until the driver has odometry."""
        if self.loop.driver.odometry is None:
            return None
        x, y, yaw = self.loop.driver.ekf.pose
        return float(x), float(y), float(yaw)

    @property
    def map_to_odom(self) -> Pose2D | None:
        return self.localizer.map_to_odom

    def amcl_pose(self) -> Pose2D | None:
        """movebase_pose2d: the current /odom pose through the last map -> odom, or None."""
        odom = self.odom_pose()
        return self.localizer.pose_from_odom(odom) if odom is not None else None

    def localization_error(self) -> tuple[float, float] | None:
        """(position [m], |heading| [rad]) of :meth:`amcl_pose` against the truth, or None."""
        est = self.amcl_pose()
        if est is None:
            return None
        tx, ty, tyaw = self.true_pose()
        return math.hypot(est[0] - tx, est[1] - ty), abs(wrap_scalar(est[2] - tyaw))

    @property
    def contact(self) -> Contact | None:
        """What the footprint touches (or was stopped by) at the last step; None: nothing."""
        return self.surroundings.contact

    @property
    def contact_events(self) -> list[ContactEvent]:
        return self.surroundings.events

    def scene_at(self, t: float) -> Scene:
        """The map and the obstacles at time ``t``, as the sensors see them."""
        if not len(self.obstacles):
            return self.scene
        return self.scene.with_solids(Solid(p.height, p.polygon, p.circle, p.name)
                                      for p in self.obstacles.prisms_at(t))

    # -- running -------------------------------------------------------------------------------
    def step(self) -> None:
        """One control period of the emulator and driver, then the sensors that are due."""
        self._advance_people(1)
        self.gate.check()
        self.loop.step()
        self._after_step()

    def _advance_people(self, periods: int) -> None:
        """The people's walks up to the end of the next ``periods`` periods, decided with the
        robot where it stands now (what the emulator's contact does before each period; the
        same decisions whether or not the contact gate installed it)."""
        if self.obstacles.people:
            tr = self.loop.mcu.truth
            self.surroundings.advance_people(self.loop.now + periods * self.control_dt,
                                             (tr.x, tr.y, tr.yaw))

    def _after_step(self) -> None:
        now = self.loop.now
        self._record_odom()
        if now + 1e-9 >= self._next_scan:
            self._next_scan += self._scan_period
            self._sense_scan(now)
        if now + 1e-9 >= self._next_frame:
            self._next_frame += self._frame_period
            assert self.camera is not None
            self.frame = self.camera.render(self.scene_at(now), self.true_pose(), now)
            self.frames += 1

    def advance(self, periods: int) -> None:
        """``periods`` of :meth:`step` (see :meth:`run_periods`)."""
        self.run_periods(periods)

    def run_periods(self, periods: int) -> int:
        """``periods`` of :meth:`step`, run by the emulator and driver in batches
        (:meth:`SimLoop.advance`) where nothing of the world's happens in between: no scan
        waiting for /odom, no camera, the contact gate's free space covering the whole run
        (:meth:`ContactGate.clear_run`), which ends at the next scan tick. /odom is recorded
        after the run: a scan tick reads only the last sample up to its stamp and the next
        one (see :meth:`odom_at`). Returns the periods with a contact."""
        contacts = 0
        while periods > 0:
            k = self._runnable(periods)
            if k > 1 and self.gate.clear_run(k):
                self._advance_people(k)  # nobody waits in the gate's slack (CLEARANCE in it)
                self.loop.advance(k)
                self._after_step()
            else:
                k = 1
                self.step()
                contacts += self.contact is not None
            periods -= k
        return contacts

    def _runnable(self, periods: int) -> int:
        """Periods from now up to and including the next scan tick, at most ``periods``; 1
        when a scan waits for /odom or the camera renders."""
        if periods < 2 or self._pending is not None or self.camera is not None:
            return 1
        t, dt = self.loop.now, self.control_dt
        for k in range(1, periods + 1):
            t += dt  # as the loop's clock advances
            if t + 1e-9 >= self._next_scan:
                return k
        return periods

    @property
    def scan(self) -> LaserScan | None:
        """The merged /scan (base_link) of the last scan tick, None before the first."""
        if self._scan is None and self._tick is not None:
            t, pose = self._tick
            self._scan = self.rig.scan(self.scene_at(t), pose, t, self._draws)
            self._draws = None
            self.scans += 1
        return self._scan

    def skip_scan(self) -> DeferredScan | None:
        """Read the last scan tick as :attr:`scan` would, but cast it only if
        :meth:`deferred_scan` is asked for it later: its random numbers are drawn now, so every
        other scan is exactly what it would have been had this one been cast (the lidars'
        generators are stateful). None before the first tick."""
        if self._tick is None:
            return None
        t, pose = self._tick
        if self._scan is not None:
            return DeferredScan(t, pose, scan=self._scan)
        if self._draws is None:
            self._draws = self.rig.draw()
        return DeferredScan(t, pose, draws=self._draws)

    def deferred_scan(self, d: DeferredScan) -> LaserScan:
        """The scan :meth:`skip_scan` stood for, bit for bit what :attr:`scan` gave then."""
        if d.scan is not None:
            return d.scan
        if self._tick is not None and self._tick[0] == d.stamp:
            if self._scan is None:
                assert self._draws is d.draws
            scan = self.scan  # cast now with its draws, or already cast (amcl) with them
            assert scan is not None
            return scan
        self.scans += 1
        return self.rig.scan(self.scene_at(d.stamp), d.pose, d.stamp, d.draws)

    def _sense_scan(self, now: float) -> None:
        self._tick = (now, self.true_pose())
        self._scan = None
        self._draws = None
        odom = self.odom_pose()
        loc = self.localizer
        if odom is None or not loc.running:
            return
        ref, p = self._fed, loc.params
        if ref is not None and math.hypot(odom[0] - ref[0], odom[1] - ref[1]) < p.update_min_d \
                and abs(wrap_scalar(odom[2] - ref[2])) < p.update_min_a:
            return  # the localizer would skip it (amcl's thresholds): no need to cast it
        self._pending = self._tick  # a newer due tick replaces one still waiting for /odom
        self._feed()

    def _record_odom(self) -> None:
        odo = self.loop.driver.odometry
        if odo is None or not math.isfinite(odo.stamp):
            return
        if self._odom_hist and odo.stamp <= self._odom_hist[-1][0]:
            return
        pose = self.odom_pose()
        assert pose is not None
        self._odom_hist = [*self._odom_hist[-1:], (odo.stamp, pose)]
        if self._pending is not None:
            self._feed()

    def odom_at(self, t: float) -> Pose2D | None:
        """/odom at time ``t``, interpolated between the samples around it (as tf2 looks up
        the odom transform at a scan's stamp); None until a sample at or after ``t`` came."""
        if not self._odom_hist or self._odom_hist[-1][0] < t:
            return None
        (t1, p1) = self._odom_hist[-1]
        if len(self._odom_hist) == 1 or t1 == t:
            return p1
        (t0, p0) = self._odom_hist[0]
        if t <= t0:
            return p0
        f = (t - t0) / (t1 - t0)
        return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]),
                wrap_scalar(p0[2] + f * wrap_scalar(p1[2] - p0[2])))

    def _feed(self) -> None:
        """Give the pending scan to the localizer with /odom at its stamp, once that exists."""
        assert self._pending is not None
        t, pose = self._pending
        odom = self.odom_at(t)
        if odom is None:
            return  # /odom has not reached the scan's stamp yet (amcl's tf message filter)
        self._pending = None
        if not self.localizer.running:
            return
        if self._tick is not None and self._tick[0] == t:
            scan = self.scan
        else:
            scan = self.rig.scan(self.scene_at(t), pose, t)
            self.scans += 1
        self._fed = odom
        est = self.localizer.update(odom, scan, truth=pose)  # type: ignore[arg-type]
        if est is not None:
            self.estimate = est

    # -- localization controls (through here, so that the next scan reaches the filter) -------
    def initial_pose(self, pose: Sequence[float], cov: Sequence[float] | None = None) -> None:
        """/initialpose (map frame); WorldError and nothing changed on bad input."""
        self.localizer.initial_pose(check_pose(pose), cov)
        self._fed = None

    def start_localization(self, on: bool) -> tuple[bool, str]:
        """/start_localization."""
        answer = self.localizer.start(on)
        self._fed = None
        return answer

