"""BMS protections: comparators with trip delay, release hysteresis and release delay.

Everything here is a pure function of (state, measurement, dt): :func:`step_limit` moves one
protection, :func:`step_protections` all of them and says which switches must be open.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

from lowerbase.bms.config import PROTECTION_DIRECTIONS, ProtectionConfig, ProtectionLimit
from lowerbase.bms.status import BmsStatus, SwitchStatus


@dataclass(frozen=True)
class LimitState:
    """State of one protection."""

    tripped: bool = False
    #: how long the trip (or, once tripped, the release) condition has held [s]
    timer_s: float = 0.0


def step_limit(
    state: LimitState, value: float, limit: ProtectionLimit, over: bool, dt: float
) -> LimitState:
    """Advance one protection by ``dt`` [s] with the measured ``value``.

    An over limit trips once ``value >= trip`` has held for ``trip_delay_s`` and releases once
    ``value <= release`` has held for ``release_delay_s`` (an under limit mirrors this). The
    timer restarts whenever its condition breaks, as a BMS's debounce counter does.
    """
    if not state.tripped:
        condition = value >= limit.trip if over else value <= limit.trip
        if not condition:
            return LimitState(False, 0.0)
        timer = state.timer_s + dt
        if timer >= limit.trip_delay_s - 1e-9:
            return LimitState(True, 0.0)
        return LimitState(False, timer)
    condition = value <= limit.release if over else value >= limit.release
    if not condition:
        return LimitState(True, 0.0)
    timer = state.timer_s + dt
    if timer >= limit.release_delay_s - 1e-9:
        return LimitState(False, 0.0)
    return LimitState(True, timer)


@dataclass(frozen=True)
class Measurements:
    """What the protections look at (SI units, current positive while charging)."""

    cell_voltage_max: float  #: [V]
    cell_voltage_min: float  #: [V]
    current: float  #: [A], + charging
    temp_max: float  #: [degC]
    temp_min: float  #: [degC]


#: protection name -> (status bit, switches it opens)
PROTECTION_ACTIONS: dict[str, tuple[BmsStatus, SwitchStatus]] = {
    "cell_ov": (BmsStatus.CELL_OVER_VOLTAGE, SwitchStatus.CHARGE),
    "cell_uv": (BmsStatus.CELL_UNDER_VOLTAGE, SwitchStatus.DISCHARGE),
    "charge_oc": (BmsStatus.CHARGE_OVER_CURRENT, SwitchStatus.CHARGE),
    "discharge_oc": (BmsStatus.DISCHARGE_OVER_CURRENT, SwitchStatus.DISCHARGE),
    "charge_ot": (BmsStatus.CHARGE_OVER_TEMPERATURE, SwitchStatus.CHARGE),
    "charge_ut": (BmsStatus.CHARGE_UNDER_TEMPERATURE, SwitchStatus.CHARGE),
    "discharge_ot": (
        BmsStatus.DISCHARGE_OVER_TEMPERATURE, SwitchStatus.CHARGE | SwitchStatus.DISCHARGE
    ),
    "discharge_ut": (BmsStatus.DISCHARGE_UNDER_TEMPERATURE, SwitchStatus.DISCHARGE),
}


def measured_value(name: str, m: Measurements) -> float:
    """The quantity protection ``name`` compares (current magnitudes in the right direction)."""
    if name == "cell_ov":
        return m.cell_voltage_max
    if name == "cell_uv":
        return m.cell_voltage_min
    if name == "charge_oc":
        return max(m.current, 0.0)
    if name == "discharge_oc":
        return max(-m.current, 0.0)
    if name in ("charge_ot", "discharge_ot"):
        return m.temp_max
    return m.temp_min


@dataclass(frozen=True)
class ProtectionState:
    """State of every protection, by name (not to be mutated: its status is kept once read)."""

    limits: dict[str, LimitState] = field(
        default_factory=lambda: {name: LimitState() for name in PROTECTION_DIRECTIONS}
    )

    @cached_property
    def status(self) -> BmsStatus:
        """Protection bits of the tripped protections."""
        bits = BmsStatus.NONE
        for name, st in self.limits.items():
            if st.tripped:
                bits |= PROTECTION_ACTIONS[name][0]
        return bits

    @cached_property
    def idle(self) -> bool:
        """No protection tripped, no timer running."""
        return all(not st.tripped and st.timer_s == 0.0 for st in self.limits.values())

    @cached_property
    def switch_bits(self) -> int:
        """:attr:`switches` as an int."""
        return int(self.switches)

    @cached_property
    def switches(self) -> SwitchStatus:
        """Switches left closed by the tripped protections."""
        closed = SwitchStatus.CHARGE | SwitchStatus.DISCHARGE
        for name, st in self.limits.items():
            if st.tripped:
                closed &= ~PROTECTION_ACTIONS[name][1]
        return closed


#: the protections in PROTECTION_DIRECTIONS order, with their direction
_DIRECTIONS: tuple[tuple[str, bool], ...] = tuple(PROTECTION_DIRECTIONS.items())
assert tuple(name for name, _ in _DIRECTIONS) == (
    "cell_ov", "cell_uv", "charge_oc", "discharge_oc", "charge_ot", "charge_ut", "discharge_ot",
    "discharge_ut"), "step_protection_values lists the measured values in this order"


_last_trips: tuple[ProtectionConfig | None, tuple[float, ...]] = (None, ())


def _trips(config: ProtectionConfig) -> tuple[float, ...]:
    """The trip points of ``config`` in _DIRECTIONS order (the last config's kept)."""
    global _last_trips
    last = _last_trips  # one read: another thread's pack may replace it meanwhile
    if last[0] is not config:
        last = (config, tuple(getattr(config, name).trip for name, _ in _DIRECTIONS))
        _last_trips = last
    return last[1]


def step_protections(
    state: ProtectionState, m: Measurements, config: ProtectionConfig, dt: float
) -> ProtectionState:
    """Advance every protection by ``dt`` [s]."""
    return step_protection_values(state, m.cell_voltage_max, m.cell_voltage_min, m.current,
                                  m.temp_max, m.temp_min, config, dt)


def step_protection_values(
    state: ProtectionState, vmax: float, vmin: float, current: float, tmax: float,
    tmin: float, config: ProtectionConfig, dt: float,
) -> ProtectionState:
    """:func:`step_protections` with the :class:`Measurements` as values. A protection that is
    clear, with no timer running and no trip condition, stays as it is without a step (what
    :func:`step_limit` would give); ``state`` itself comes back when every one did."""
    values = (vmax, vmin, max(current, 0.0), max(-current, 0.0), tmax, tmin, tmax, tmin)
    if state.idle:  # the usual case: every value on the safe side of its trip
        t = _trips(config)
        if (vmax < t[0] and vmin > t[1] and values[2] < t[2] and values[3] < t[3]
                and tmax < t[4] and tmin > t[5] and tmax < t[6] and tmin > t[7]):
            return state
    limits = state.limits
    changed: dict[str, LimitState] | None = None
    for (name, over), value in zip(_DIRECTIONS, values, strict=True):  # measured_value each
        old = limits[name]
        limit: ProtectionLimit = getattr(config, name)
        if not old.tripped and old.timer_s == 0.0 and not (
                value >= limit.trip if over else value <= limit.trip):
            continue
        if changed is None:
            changed = dict(limits)
        changed[name] = step_limit(old, value, limit, over, dt)
    return state if changed is None else ProtectionState(changed)
