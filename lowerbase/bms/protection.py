"""BMS protections: comparators with trip delay, release hysteresis and release delay.

Everything here is a pure function of (state, measurement, dt): :func:`step_limit` moves one
protection, :func:`step_protections` all of them and says which switches must be open.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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
    """State of every protection, by name."""

    limits: dict[str, LimitState] = field(
        default_factory=lambda: {name: LimitState() for name in PROTECTION_DIRECTIONS}
    )

    @property
    def status(self) -> BmsStatus:
        """Protection bits of the tripped protections."""
        bits = BmsStatus.NONE
        for name, st in self.limits.items():
            if st.tripped:
                bits |= PROTECTION_ACTIONS[name][0]
        return bits

    @property
    def switches(self) -> SwitchStatus:
        """Switches left closed by the tripped protections."""
        closed = SwitchStatus.CHARGE | SwitchStatus.DISCHARGE
        for name, st in self.limits.items():
            if st.tripped:
                closed &= ~PROTECTION_ACTIONS[name][1]
        return closed


def step_protections(
    state: ProtectionState, m: Measurements, config: ProtectionConfig, dt: float
) -> ProtectionState:
    """Advance every protection by ``dt`` [s]."""
    return ProtectionState(
        {
            name: step_limit(
                state.limits[name], measured_value(name, m), getattr(config, name), over, dt
            )
            for name, over in PROTECTION_DIRECTIONS.items()
        }
    )
