"""Pack physics against closed-form answers (simulated time only)."""

from __future__ import annotations

import itertools
import math

import pytest

from lowerbase.bms.config import BatteryConfig, default_battery_config
from lowerbase.bms.ocv import OCV_TABLES, SOC_GRID, Chemistry, cell_ocv, soc_from_ocv
from lowerbase.bms.pack import (
    BatteryPack,
    average_step,
    cc_cv_current,
    coulomb_step,
    terminal_voltage,
    thermal_step,
    time_remaining_min,
)
from lowerbase.bms.snapshot import TIME_REMAIN_NOT_DISCHARGING
from lowerbase.bms.status import BmsStatus, ChargeMode, SwitchStatus


def test_coulomb_step_is_i_times_t() -> None:
    assert coulomb_step(20.0, -10.0, 360.0, 40.0) == pytest.approx(19.0)
    assert coulomb_step(20.0, 5.0, 720.0, 40.0) == pytest.approx(21.0)
    assert coulomb_step(0.5, -10.0, 3600.0, 40.0) == 0.0  # clamped empty
    assert coulomb_step(39.9, 10.0, 3600.0, 40.0) == 40.0  # clamped full


@pytest.mark.parametrize("chem", list(Chemistry))
def test_ocv_table_end_points_and_grid(chem: Chemistry) -> None:
    table = OCV_TABLES[chem]
    assert cell_ocv(chem, 0.0) == table[0]
    assert cell_ocv(chem, 100.0) == table[-1]
    assert cell_ocv(chem, -5.0) == table[0] and cell_ocv(chem, 150.0) == table[-1]
    for soc, v in zip(SOC_GRID, table, strict=True):
        assert cell_ocv(chem, soc) == pytest.approx(v)
    assert all(b > a for a, b in itertools.pairwise(table)), "strictly increasing"
    # half way between two grid points is the mean
    assert cell_ocv(chem, 45.0) == pytest.approx((table[5] + table[6]) / 2)
    assert soc_from_ocv(chem, cell_ocv(chem, 37.0)) == pytest.approx(37.0)


def test_lfp_table_matches_physical_data() -> None:
    assert cell_ocv(Chemistry.LFP, 0) == 2.010 and cell_ocv(Chemistry.LFP, 100) == 3.598
    assert cell_ocv(Chemistry.NMC, 0) == 2.557 and cell_ocv(Chemistry.NMC, 100) == 4.194
    # the LFP plateau: 30-90 % within about 60 mV
    assert cell_ocv(Chemistry.LFP, 90) - cell_ocv(Chemistry.LFP, 30) == pytest.approx(0.063)


def test_terminal_voltage_is_ocv_minus_i_r() -> None:
    assert terminal_voltage(52.0, -20.0, 0.03) == pytest.approx(51.4)
    assert terminal_voltage(52.0, 10.0, 0.03) == pytest.approx(52.3)


def test_thermal_step_closed_form() -> None:
    c, r = 15000.0, 0.4
    tau = c * r
    # heating from ambient: T = Ta + P R (1 - exp(-t/tau))
    t = thermal_step(25.0, 25.0, 10.0, c, r, 3000.0)
    assert t == pytest.approx(25.0 + 10.0 * r * (1 - math.exp(-3000.0 / tau)))
    # cooling without power: exponential decay to ambient
    assert thermal_step(45.0, 25.0, 0.0, c, r, tau) == pytest.approx(25.0 + 20.0 / math.e)
    # two half steps equal one step (exact integration)
    half = thermal_step(thermal_step(30.0, 25.0, 7.0, c, r, 50.0), 25.0, 7.0, c, r, 50.0)
    assert half == pytest.approx(thermal_step(30.0, 25.0, 7.0, c, r, 100.0))


def test_cc_cv_current() -> None:
    assert cc_cv_current(50.0, 57.6, 0.03, 20.0) == 20.0  # CC: far below CV
    assert cc_cv_current(57.3, 57.6, 0.03, 20.0) == pytest.approx(10.0)  # CV
    assert cc_cv_current(58.0, 57.6, 0.03, 20.0) == 0.0  # never discharges


def test_average_and_time_remaining() -> None:
    assert average_step(0.0, -10.0, 60.0, 60.0) == pytest.approx(-10.0 * (1 - math.exp(-1)))
    assert time_remaining_min(20.0, -10.0) == pytest.approx(120.0)
    assert time_remaining_min(20.0, 0.0) == TIME_REMAIN_NOT_DISCHARGING
    assert time_remaining_min(20.0, 3.0) == TIME_REMAIN_NOT_DISCHARGING


def test_constant_load_lowers_charge_by_i_t_including_idle() -> None:
    cfg = BatteryConfig()
    pack = BatteryPack(cfg, soc=80.0)
    before = pack.charge_ah
    for _ in range(600):
        pack.step(1.0, 15.0)
    drawn = (15.0 + cfg.idle_current_a) * 600.0 / 3600.0
    assert before - pack.charge_ah == pytest.approx(drawn)
    assert pack.current == pytest.approx(-(15.0 + cfg.idle_current_a))
    assert pack.time_s == pytest.approx(600.0)


def test_idle_draw_at_rest() -> None:
    pack = BatteryPack(soc=50.0)
    before = pack.charge_ah
    pack.step(3600.0)  # one hour, split into substeps internally
    assert before - pack.charge_ah == pytest.approx(pack.config.idle_current_a)


def test_snapshot_voltage_is_ocv_minus_ir_and_cells_bracket_it() -> None:
    cfg = BatteryConfig()
    pack = BatteryPack(cfg, soc=60.0)
    pack.step(0.1, 30.0)
    snap = pack.snapshot()
    i = -(30.0 + cfg.idle_current_a)
    assert snap.current == pytest.approx(i)
    ocv = cfg.cells_series * cell_ocv(cfg.chemistry, pack.soc)
    assert snap.voltage == pytest.approx(ocv + i * cfg.internal_resistance_ohm)
    assert snap.cell_voltage_max >= snap.voltage / cfg.cells_series >= snap.cell_voltage_min
    assert snap.temp_max - snap.temp_min == pytest.approx(cfg.temp_sensor_spread_c)
    assert snap.capacity_design >= snap.capacity_full >= snap.capacity_remain


def test_cell_spread_grows_at_the_knee() -> None:
    mid = BatteryPack(soc=50.0).snapshot()
    low = BatteryPack(soc=3.0).snapshot()
    assert mid.cell_voltage_max - mid.cell_voltage_min < 0.005
    assert low.cell_voltage_max - low.cell_voltage_min > 0.1


def test_temperature_rises_with_i2r_and_cools_to_ambient() -> None:
    cfg = BatteryConfig()
    pack = BatteryPack(cfg, soc=100.0)
    pack.step(1800.0, 40.0)
    i = 40.0 + cfg.idle_current_a
    power = i * i * cfg.internal_resistance_ohm
    tau = cfg.thermal_mass_j_per_k * cfg.thermal_resistance_k_per_w
    expected = cfg.ambient_temp_c + power * cfg.thermal_resistance_k_per_w * (
        1 - math.exp(-1800.0 / tau)
    )
    assert pack.temperature == pytest.approx(expected, rel=1e-9)
    hot = pack.temperature
    pack.step(5 * tau, 0.0)  # only the idle draw heats now
    idle_steady = cfg.ambient_temp_c + (
        cfg.idle_current_a**2 * cfg.internal_resistance_ohm * cfg.thermal_resistance_k_per_w
    )
    assert cfg.ambient_temp_c < pack.temperature < hot
    assert pack.temperature == pytest.approx(
        idle_steady + (hot - idle_steady) * math.exp(-5), rel=1e-6
    )


def test_cc_cv_charge_to_full_counts_a_cycle() -> None:
    cfg = BatteryConfig()
    pack = BatteryPack(cfg, soc=0.0)
    pack.connect_charger(ChargeMode.MANUAL)
    pack.step(1.0)
    assert pack.current == pytest.approx(cfg.charge_current_a)
    snap = pack.snapshot()
    assert snap.charge_status == 1 and snap.charge_mode == 0
    assert snap.bms_status & BmsStatus.CHARGING and snap.bms_status & BmsStatus.CHARGER_CONNECTED
    saw_cv = False
    for _ in range(4 * 3600):
        pack.step(1.0)
        if 0 < pack.current < cfg.charge_current_a - 0.1:
            saw_cv = True
        if pack.status & BmsStatus.FULLY_CHARGED:
            break
    assert saw_cv, "the current tapers in the CV phase"
    assert pack.status & BmsStatus.FULLY_CHARGED
    assert pack.soc == pytest.approx(100.0)
    assert pack.current == 0.0
    assert pack.charge_cycles == cfg.charge_cycles + 1
    # the pack never went over the CV voltage by more than the I*R of the CC current
    assert pack.snapshot().cell_voltage_max < cfg.protection.cell_ov.trip


def test_charging_derated_when_cold() -> None:
    cfg = BatteryConfig(ambient_temp_c=10.0)
    pack = BatteryPack(cfg, soc=50.0)
    pack.connect_charger()
    pack.step(1.0)
    assert pack.current == pytest.approx(cfg.cold_charge_current_a)


def test_full_discharge_ends_in_under_voltage_cut_off() -> None:
    pack = BatteryPack(soc=100.0)
    seconds = 0
    while pack.switches & SwitchStatus.DISCHARGE and seconds < 10 * 3600:
        pack.step(1.0, 20.0)
        seconds += 1
    assert pack.status & BmsStatus.CELL_UNDER_VOLTAGE
    assert pack.switches == SwitchStatus.CHARGE
    # 38.8 Ah at 21 A is 1.85 h; the cut-off leaves a few % in the pack
    assert 0.9 * 38.8 / 21 * 3600 < seconds < 38.8 / 21 * 3600
    assert 0 < pack.soc < 6
    pack.step(10.0, 20.0)
    assert pack.current == 0.0, "no current through the open discharge switch"
    assert pack.snapshot().time_remain == TIME_REMAIN_NOT_DISCHARGING or pack.soc > 0


def test_nmc_defaults() -> None:
    cfg = default_battery_config("nmc")
    assert cfg.chemistry is Chemistry.NMC and cfg.cells_series == 13
    pack = BatteryPack(cfg, soc=100.0)
    assert pack.ocv() == pytest.approx(13 * 4.194)
