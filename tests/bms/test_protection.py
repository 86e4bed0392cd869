"""Every protection trips at its threshold after its delay and clears with hysteresis."""

from __future__ import annotations

import dataclasses

import pytest

from lowerbase.bms.config import PROTECTION_DIRECTIONS, BatteryConfig, ProtectionLimit
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.protection import (
    PROTECTION_ACTIONS,
    LimitState,
    Measurements,
    ProtectionState,
    measured_value,
    step_limit,
    step_protections,
)
from lowerbase.bms.status import PROTECTION_MASK, BmsStatus, SwitchStatus

DT = 0.01  # [s]
PROTECTION = BatteryConfig().protection


def run(state: LimitState, value: float, limit: ProtectionLimit, over: bool, seconds: float
        ) -> LimitState:
    for _ in range(round(seconds / DT)):
        state = step_limit(state, value, limit, over, DT)
    return state


@pytest.mark.parametrize("name", list(PROTECTION_DIRECTIONS))
def test_trips_at_threshold_after_delay_and_releases_with_hysteresis(name: str) -> None:
    limit: ProtectionLimit = getattr(PROTECTION, name)
    over = PROTECTION_DIRECTIONS[name]
    away = 1.0 if over else -1.0  # direction of "worse"
    margin = 0.001
    normal = limit.release - away * 1.0
    st = run(LimitState(), normal, limit, over, 10.0)
    assert not st.tripped
    # just short of the trip value: never trips
    st = run(st, limit.trip - away * margin, limit, over, 10 * limit.trip_delay_s + 1)
    assert not st.tripped
    # at the trip value: not before the delay, but at it
    before = max(limit.trip_delay_s - 2 * DT, 0.0)
    st = run(LimitState(), limit.trip, limit, over, before)
    assert not st.tripped or limit.trip_delay_s < 2 * DT
    st = run(LimitState(), limit.trip, limit, over, limit.trip_delay_s)
    assert st.tripped
    # a glitch shorter than the delay restarts the debounce
    glitch = run(LimitState(), limit.trip, limit, over, limit.trip_delay_s / 2)
    glitch = step_limit(glitch, normal, limit, over, DT)
    glitch = run(glitch, limit.trip, limit, over, limit.trip_delay_s / 2)
    assert not glitch.tripped or limit.trip_delay_s < 4 * DT
    # back between release and trip (the hysteresis band): stays tripped
    band = (limit.trip + limit.release) / 2
    st = run(st, band, limit, over, 60.0 + limit.release_delay_s)
    assert st.tripped
    # past the release value: clears after the release delay, not before
    if limit.release_delay_s > 0:
        early = run(st, limit.release, limit, over, limit.release_delay_s - 2 * DT)
        assert early.tripped
    st = run(st, limit.release, limit, over, max(limit.release_delay_s, DT))
    assert not st.tripped


def _measurements(**kw: float) -> Measurements:
    base = {"cell_voltage_max": 3.3, "cell_voltage_min": 3.3, "current": 0.0,
            "temp_max": 25.0, "temp_min": 25.0}
    base.update(kw)
    return Measurements(**base)


@pytest.mark.parametrize(
    ("name", "kw"),
    [
        ("cell_ov", {"cell_voltage_max": 3.70}),
        ("cell_uv", {"cell_voltage_min": 2.40}),
        ("charge_oc", {"current": 50.0}),
        ("discharge_oc", {"current": -90.0}),
        ("charge_ot", {"temp_max": 50.0}),
        ("charge_ut", {"temp_min": -1.0}),
        ("discharge_ot", {"temp_max": 70.0}),
        ("discharge_ut", {"temp_min": -25.0}),
    ],
)
def test_status_bits_and_switches(name: str, kw: dict[str, float]) -> None:
    m = _measurements(**kw)
    state = ProtectionState()
    for _ in range(300):
        state = step_protections(state, m, PROTECTION, DT)
    bit, opens = PROTECTION_ACTIONS[name]
    # charge_ot fires with discharge_ot's temperature too, and charge_ut with discharge_ut's
    assert state.status & bit
    assert not state.switches & opens
    assert state.status & ~PROTECTION_MASK == 0
    value = next(iter(kw.values()))
    assert measured_value(name, m) == pytest.approx(abs(value) if "oc" in name else value)


def test_discharge_over_temperature_opens_both_switches() -> None:
    state = ProtectionState()
    for _ in range(300):
        state = step_protections(state, _measurements(temp_max=70.0), PROTECTION, DT)
    assert state.switches == SwitchStatus.NONE


def test_pack_over_current_trips_and_releases_after_delay() -> None:
    pack = BatteryPack(soc=80.0)
    trip = pack.config.protection.discharge_oc
    load = trip.trip + 5.0
    pack.step(trip.trip_delay_s - 0.1, load)
    assert pack.switches & SwitchStatus.DISCHARGE
    pack.step(0.2, load)
    assert pack.status & BmsStatus.DISCHARGE_OVER_CURRENT
    assert not pack.switches & SwitchStatus.DISCHARGE
    pack.step(1.0, load)
    assert pack.current == 0.0  # the open switch carries nothing
    pack.step(trip.release_delay_s - 2.0, load)
    assert pack.status & BmsStatus.DISCHARGE_OVER_CURRENT
    pack.step(2.0, 10.0)
    assert not pack.status & BmsStatus.DISCHARGE_OVER_CURRENT
    pack.step(1.0, 10.0)
    assert pack.current == pytest.approx(-(10.0 + pack.config.idle_current_a))


def test_pack_under_voltage_releases_when_charged() -> None:
    pack = BatteryPack(soc=4.0)
    while pack.switches & SwitchStatus.DISCHARGE:
        pack.step(1.0, 30.0)
    assert pack.status & BmsStatus.CELL_UNDER_VOLTAGE
    pack.step(600.0, 30.0)  # resting: the cells recover only to their OCV, below release
    assert pack.status & BmsStatus.CELL_UNDER_VOLTAGE
    pack.connect_charger()
    pack.step(600.0)
    assert not pack.status & BmsStatus.CELL_UNDER_VOLTAGE
    assert pack.switches == SwitchStatus.CHARGE | SwitchStatus.DISCHARGE


def test_cold_pack_does_not_charge() -> None:
    pack = BatteryPack(BatteryConfig(ambient_temp_c=-5.0), soc=50.0)
    pack.connect_charger()
    pack.step(5.0)
    assert pack.status & BmsStatus.CHARGE_UNDER_TEMPERATURE
    assert pack.current == 0.0
    assert pack.switches == SwitchStatus.DISCHARGE


def test_lowered_ov_threshold_stops_charging() -> None:
    pack = BatteryPack(soc=99.0)
    p = pack.config.protection
    with pytest.raises(Exception, match="below the cell OV trip"):
        pack.set_protection(dataclasses.replace(p, cell_ov=ProtectionLimit(3.55, 3.40)))
    pack.set_protection(dataclasses.replace(p, soc_low_percent=99.5))
    assert pack.status & BmsStatus.SOC_LOW
