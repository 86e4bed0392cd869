"""The task machine on the whole emulated robot, on the simulated clock: :class:`TaskSim`.

A :class:`TaskSim` runs a :class:`~lowerbase.tasks.machine.TaskMachine` on a
:class:`~lowerbase.navigation.sim.NavSim` (navigator + WorldSim: emulator, driver core, map,
lidars, localization). Every control period (20 Hz) it reads the chassis as driver_base sees it
(:func:`chassis_from_driver`: link, e-stop, faults, the BMS frames) and the localization
estimate, ticks the machine, and sends the machine's twist through the driver when navigation
does not (the docking moves). The navigator itself is ticked by the NavSim.

The charger: its contact closes when the robot truly stands on the map's charger pose (within
``contact_tolerance`` / ``contact_yaw``) and opens when it leaves; closing it is the emulator's
existing charger input (``mcu.bms.connect_charger``), so the BMS charges CC-CV and reports it in
its frames, which is what the machine waits for.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from lowerbase.bms.status import BmsStatus, ChargeMode
from lowerbase.driver.core import DriverCore, LinkState
from lowerbase.navigation.controller import Status as CtrlStatus
from lowerbase.navigation.navigator import GoalState, NavCommand
from lowerbase.navigation.sim import NavSim
from lowerbase.protocol.status_codes import StatusBit
from lowerbase.simloop.loop import TickedLoop
from lowerbase.tasks.inputs import FAULT_BITS, faults_of
from lowerbase.tasks.machine import TaskMachine
from lowerbase.tasks.model import Pose, Status, TaskRequest, TaskResponse
from lowerbase.tasks.plan import TaskConfig
from lowerbase.tasks.status import Chassis
from lowerbase.world.charger import CONTACT_TOLERANCE, CONTACT_YAW, on_charger
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.places import Places, load_places
from lowerbase.world.sim import WorldSim

#: the status code's bits as ints (IntFlag arithmetic costs microseconds a tick)
_LOW, _CRITICAL = int(StatusBit.LOW_BATTERY), int(StatusBit.CRITICAL_BATTERY)
_FAULT_MASK = 0
for _bit in FAULT_BITS:
    _FAULT_MASK |= int(_bit)
_CHARGER = int(BmsStatus.CHARGER_CONNECTED)
_faults: dict[int, str] = {}  #: faults_of by the code's fault bits


def chassis_from_driver(driver: DriverCore, pose: Pose | None, localized: bool = True
                        ) -> Chassis:
    """The chassis as driver_base's core shows it (``pose``: the localization estimate). The
    BMS's state of charge and status word are read off its frames as ``snapshot()`` reads them
    (``float(Soc)``, ``int(Status)``), without building the whole snapshot every tick."""
    code = int(driver.status_code)
    bms = driver.bms
    soc, charging = None, False
    if bms.complete:
        soc = float(bms.frames["BmsPack"]["Soc"])
        charging = bool(int(bms.frames["BmsStatus"]["Status"]) & _CHARGER)
    odom = None
    if driver.odometry is not None:
        x, y, yaw = driver.ekf.pose
        odom = (float(x), float(y), float(yaw))
    fault_bits = code & _FAULT_MASK
    fault = _faults.get(fault_bits)
    if fault is None:
        fault = _faults.setdefault(fault_bits, faults_of(fault_bits))
    state = driver.state
    return Chassis(
        initialized=state in (LinkState.READY, LinkState.STANDBY)
        or (state == LinkState.LOST and odom is not None),
        link_lost=state == LinkState.LOST,
        e_stopped=driver.e_stopped,
        fault=fault,
        soc=soc,
        low_battery=bool(code & _LOW),
        critical_battery=bool(code & _CRITICAL),
        charging=charging,
        localized=localized and pose is not None,
        pose=pose, odom=odom)


class NavSimNavigation:
    """The machine's Navigation on a NavSim: goals go to its Navigator; ``tick`` reports the
    navigator's state and the last command the NavSim computed (the NavSim sends its twist)."""

    def __init__(self, navsim: NavSim) -> None:
        self.navsim = navsim

    def send_goal(self, target: Pose, poses: Sequence[Pose] = (), execution_mode: int = 0,
                  now: float = 0.0) -> None:
        self.navsim.navigator.send_goal(target, poses, execution_mode, now)

    def cancel(self, now: float) -> None:
        self.navsim.navigator.cancel(now)

    def tick(self, now: float, pose: Pose) -> NavCommand:
        nav, last = self.navsim.navigator, self.navsim.last
        state = nav.state if nav.state is not None else GoalState.PENDING
        if last is None or state == GoalState.PENDING:
            return NavCommand(0.0, 0.0, state, CtrlStatus.IDLE, nav.reason)
        return NavCommand(last.linear, last.angular, state, last.status, nav.reason)


class TaskSim(TickedLoop):
    """A TaskMachine on a NavSim (see the module docstring)."""

    def __init__(self, navsim: NavSim, places: Places | None = None,
                 config: TaskConfig | None = None, *,
                 contact_tolerance: float = CONTACT_TOLERANCE, contact_yaw: float = CONTACT_YAW,
                 on_status: Callable[[Status], None] | None = None) -> None:
        self.navsim = navsim
        world = navsim.world
        if places is None:
            ref = world.config.map
            places = Places() if isinstance(ref, OccupancyGrid) else load_places(ref, world.grid)
        self.places = places
        self.machine = TaskMachine(NavSimNavigation(navsim), places, config,
                                   on_status=on_status)
        self.contact_tolerance = contact_tolerance
        self.contact_yaw = contact_yaw
        self.charger_closed = False
        self.twist: tuple[float, float] | None = None

    @property
    def world(self) -> WorldSim:
        return self.navsim.world

    @property
    def now(self) -> float:
        return self.navsim.now

    @property
    def status(self) -> Status:
        current = self.machine.tracker.current
        assert current is not None
        return current

    def request(self, req: TaskRequest) -> TaskResponse:
        return self.machine.request(req, self.now)

    def on_charger(self) -> bool:
        """The robot truly stands on the charger's contacts."""
        return on_charger(self.world.true_pose(), self.places.charger, self.contact_tolerance,
                          self.contact_yaw)

    def _charger(self) -> None:
        bms = self.world.loop.mcu.bms
        on = self.on_charger()
        if on != self.charger_closed and bms is not None:
            if on:
                bms.connect_charger(ChargeMode.AUTO)
            else:
                bms.disconnect_charger()
            self.charger_closed = on

    def tick(self) -> None:
        """One control period: charger contact, chassis, machine, twist, navigation, world."""
        self._charger()
        w = self.world
        est = w.amcl_pose()
        ch = chassis_from_driver(w.loop.driver, est, w.localizer.running)
        self.twist = self.machine.tick(self.now, ch)
        if self.twist is not None and not self._navigating():
            w.loop.driver.set_twist(*self.twist)
        self.navsim.tick()

    def _navigating(self) -> bool:
        return self.navsim.navigator.state in (GoalState.PENDING, GoalState.ACTIVE)

