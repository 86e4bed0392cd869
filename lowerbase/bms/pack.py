"""The battery pack model: coulomb counting, OCV + I*R, heat, CC-CV charging, protections.

Small pure functions hold the physics (each tested against its closed form); :class:`BatteryPack`
strings them together. The pack never reads a clock: :meth:`BatteryPack.step` takes ``dt``.

Sign convention: pack current is positive while charging, negative while discharging
(sensor_msgs/BatteryState and the CAN catalog), so terminal voltage = OCV + I*R, i.e.
OCV - I_discharge*R.
"""

from __future__ import annotations

import dataclasses
import math

from lowerbase.bms.config import BatteryConfig, ProtectionConfig
from lowerbase.bms.ocv import cell_ocv
from lowerbase.bms.protection import ProtectionState, step_protection_values
from lowerbase.bms.snapshot import TIME_REMAIN_NOT_DISCHARGING, BmsSnapshot
from lowerbase.bms.status import BmsStatus, ChargeMode, ChargeStatus, SwitchStatus
from lowerbase.errors import ConfigError

#: longest integration step [s]; longer steps are split (CV phase and delays stay accurate)
MAX_SUBSTEP_S = 1.0
#: average discharge current below which time-remaining reports "not discharging" [A]
MIN_DISCHARGE_A = 0.05
_SOC_LOW, _CHARGER_CONNECTED = int(BmsStatus.SOC_LOW), int(BmsStatus.CHARGER_CONNECTED)
_FULLY_CHARGED, _CHARGING = int(BmsStatus.FULLY_CHARGED), int(BmsStatus.CHARGING)
_CHARGING_STATUS, _DISCHARGE_STATUS = int(ChargeStatus.CHARGING), int(ChargeStatus.DISCHARGE)
_CHARGE_SWITCH, _DISCHARGE_SWITCH = int(SwitchStatus.CHARGE), int(SwitchStatus.DISCHARGE)


def coulomb_step(charge_ah: float, current_a: float, dt_s: float, capacity_ah: float) -> float:
    """Charge [Ah] after ``current_a`` [A] (+ charging) for ``dt_s`` [s], within [0, capacity]."""
    return min(max(charge_ah + current_a * dt_s / 3600.0, 0.0), capacity_ah)


def terminal_voltage(ocv_v: float, current_a: float, resistance_ohm: float) -> float:
    """Terminal voltage [V] = OCV + I*R with I [A] positive while charging."""
    return ocv_v + current_a * resistance_ohm


def thermal_step(
    temp_c: float, ambient_c: float, power_w: float, thermal_mass_j_per_k: float,
    thermal_resistance_k_per_w: float, dt_s: float,
) -> float:
    """Temperature [degC] after ``dt_s`` [s] of ``power_w`` [W] heating and cooling to ambient.

    Exact solution of C dT/dt = P - (T - T_amb)/R_th for constant P: T relaxes towards
    T_amb + P*R_th with time constant R_th*C.
    """
    steady = ambient_c + power_w * thermal_resistance_k_per_w
    tau = thermal_resistance_k_per_w * thermal_mass_j_per_k
    return steady + (temp_c - steady) * math.exp(-dt_s / tau)


def cc_cv_current(
    ocv_v: float, cv_voltage_v: float, resistance_ohm: float, cc_current_a: float
) -> float:
    """Charge current [A] of a CC-CV charger: the CC limit, or whatever holds the terminal at
    ``cv_voltage_v`` [V] through ``resistance_ohm`` once that is smaller (never negative)."""
    return max(0.0, min(cc_current_a, (cv_voltage_v - ocv_v) / resistance_ohm))


def average_step(average: float, value: float, dt_s: float, tau_s: float) -> float:
    """First-order low-pass (exponential moving average) of ``value`` over ``dt_s`` [s]."""
    return value + (average - value) * math.exp(-dt_s / tau_s)


def time_remaining_min(capacity_remain_ah: float, average_current_a: float) -> float:
    """Minutes to empty at ``average_current_a`` [A] (+ charging); 65535 when not discharging."""
    if average_current_a > -MIN_DISCHARGE_A:
        return TIME_REMAIN_NOT_DISCHARGING
    return min(capacity_remain_ah / -average_current_a * 60.0, TIME_REMAIN_NOT_DISCHARGING - 1)


class BatteryPack:
    """A series pack with a BMS: call :meth:`step` with the motors' load current.

    ``soc`` is the initial state of charge [%]; ``temperature_c`` the initial pack temperature
    (default: ambient).
    """

    def __init__(
        self, config: BatteryConfig | None = None, *, soc: float = 100.0,
        temperature_c: float | None = None,
    ) -> None:
        self.config = config or BatteryConfig()
        if not (isinstance(soc, (int, float)) and 0.0 <= soc <= 100.0):
            raise ConfigError(f"initial SOC must be within 0-100 %, got {soc!r}")
        c = self.config
        self._charge_ah = c.capacity_ah * soc / 100.0
        self._temp_c = c.ambient_temp_c if temperature_c is None else float(temperature_c)
        self._current_a = 0.0
        self._avg_current_a = -c.idle_current_a
        self._charged_ah = 0.0  # charge throughput since start, for the cycle count
        self._charger_connected = False
        self._charge_mode = ChargeMode.MANUAL
        self._charge_complete = False
        self._protection = ProtectionState()
        self._load_a = 0.0
        self.time_s = 0.0  #: simulated time stepped so far [s]

    # -- inputs ---------------------------------------------------------------------------

    def connect_charger(self, mode: ChargeMode | int = ChargeMode.AUTO) -> None:
        """Connect a CC-CV charger (``mode``: AUTO = docking station, MANUAL = plugged)."""
        self._charge_mode = ChargeMode(mode)
        if not self._charger_connected:
            self._charger_connected = True
            self._charge_complete = False

    def disconnect_charger(self) -> None:
        """Take the charger away."""
        self._charger_connected = False
        self._charge_complete = False

    @property
    def charger_connected(self) -> bool:
        return self._charger_connected

    def set_protection(self, protection: ProtectionConfig) -> None:
        """Replace the thresholds (what a Modbus write of the threshold registers does).

        Raises :class:`ConfigError` (and changes nothing) when they do not fit the pack.
        """
        self.config = dataclasses.replace(self.config, protection=protection)

    # -- state ----------------------------------------------------------------------------

    @property
    def soc(self) -> float:
        """State of charge [%] by coulomb counting."""
        return 100.0 * self._charge_ah / self.config.capacity_ah

    @property
    def charge_ah(self) -> float:
        """Remaining charge [Ah]."""
        return self._charge_ah

    @property
    def current(self) -> float:
        """Pack current of the last step [A], + charging."""
        return self._current_a

    @property
    def temperature(self) -> float:
        """Pack (mean) temperature [degC]."""
        return self._temp_c

    @property
    def switches(self) -> SwitchStatus:
        """Closed MOSFET switches."""
        return self._protection.switches

    @property
    def status(self) -> BmsStatus:
        """The full status word."""
        return BmsStatus(self._status_word())

    def _status_word(self) -> int:
        """:attr:`status` as an int (flag arithmetic on ints: the same bits)."""
        bits = int(self._protection.status)
        if self.soc < self.config.protection.soc_low_percent:
            bits |= _SOC_LOW
        if self._charger_connected:
            bits |= _CHARGER_CONNECTED
            if self._charge_complete:
                bits |= _FULLY_CHARGED
        if self._current_a > 0:
            bits |= _CHARGING
        return bits

    @property
    def charge_cycles(self) -> int:
        """Completed charge cycles: the start count plus charge throughput / full capacity."""
        return self.config.charge_cycles + int(self._charged_ah / self.config.capacity_ah)

    def ocv(self) -> float:
        """Pack open-circuit voltage [V]."""
        return self.config.cells_series * cell_ocv(self.config.chemistry, self.soc)

    def voltage(self) -> float:
        """Pack terminal voltage [V] at the last step's current."""
        return terminal_voltage(self.ocv(), self._current_a, self.config.internal_resistance_ohm)

    def cell_voltages(self) -> tuple[float, float]:
        """(highest, lowest) cell terminal voltage [V]: the SOC spread through the OCV table,
        plus each cell's share of I*R."""
        c = self.config
        half = c.cell_soc_spread_percent / 2.0
        drop = self._current_a * c.cell_resistance_ohm
        soc = self.soc
        return (
            cell_ocv(c.chemistry, min(soc + half, 100.0)) + drop,
            cell_ocv(c.chemistry, max(soc - half, 0.0)) + drop,
        )

    def temperatures(self) -> tuple[float, float]:
        """(hottest, coldest) sensor [degC]."""
        half = self.config.temp_sensor_spread_c / 2.0
        return self._temp_c + half, self._temp_c - half

    # -- simulation -----------------------------------------------------------------------

    def _battery_current(self, load_a: float) -> float:
        """Current into the pack [A] for this step, given the switches and the charger."""
        c = self.config
        switches = self._protection.switch_bits
        if self._charger_connected:
            # the charger carries the robot's load; the pack gets the CC-CV current
            if self._charge_complete or not switches & _CHARGE_SWITCH:
                return 0.0
            cc = c.charge_current_a if self._temp_c >= 15.0 else c.cold_charge_current_a
            current = cc_cv_current(
                self.ocv(), c.charge_voltage_per_cell_v * c.cells_series,
                c.internal_resistance_ohm, cc,
            )
            if current < c.charge_termination_a:
                self._charge_complete = True
                # a BMS recalibrates to 100 % at termination; the jump counts as charge
                self._charged_ah += c.capacity_ah - self._charge_ah
                self._charge_ah = c.capacity_ah
                return 0.0
            return current
        if not switches & _DISCHARGE_SWITCH:
            return 0.0
        return -(max(load_a, 0.0) + c.idle_current_a)

    def step(self, dt: float, load_current: float = 0.0) -> None:
        """Advance the pack by ``dt`` [s] while the motors draw ``load_current`` [A] (>= 0).

        The idle draw is added here. No current flows through an open switch.
        """
        if not (dt >= 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a finite number >= 0, got {dt!r}")
        if not math.isfinite(load_current):
            raise ValueError(f"load current must be finite, got {load_current!r}")
        remaining = dt
        while remaining > 1e-12:
            h = min(remaining, MAX_SUBSTEP_S)
            self._substep(h, load_current)
            remaining -= h

    def _substep(self, dt: float, load_a: float) -> None:
        c = self.config
        current = self._battery_current(load_a)
        self._current_a = current
        self._charge_ah = coulomb_step(self._charge_ah, current, dt, c.capacity_ah)
        if current > 0:
            self._charged_ah += current * dt / 3600.0
        self._temp_c = thermal_step(
            self._temp_c, c.ambient_temp_c, current * current * c.internal_resistance_ohm,
            c.thermal_mass_j_per_k, c.thermal_resistance_k_per_w, dt,
        )
        self._avg_current_a = average_step(self._avg_current_a, current, dt, c.current_average_s)
        vmax, vmin = self.cell_voltages()
        tmax, tmin = self.temperatures()
        self._protection = step_protection_values(
            self._protection, vmax, vmin, current, tmax, tmin, c.protection, dt
        )
        self.time_s += dt

    # -- output ---------------------------------------------------------------------------

    def snapshot(self) -> BmsSnapshot:
        """The BMS reading now, at full precision (registers and frames quantize it)."""
        c = self.config
        vmax, vmin = self.cell_voltages()
        tmax, tmin = self.temperatures()
        return BmsSnapshot(
            voltage=self.voltage(),
            current=self._current_a,
            soc=self.soc,
            cell_voltage_max=vmax,
            cell_voltage_min=vmin,
            temp_max=tmax,
            temp_min=tmin,
            capacity_remain=self._charge_ah,
            capacity_full=c.capacity_ah,
            capacity_design=c.design_capacity_ah,
            bms_status=self._status_word(),
            charge_cycle=min(self.charge_cycles, 65535),
            battery_cycle=c.cycle_life,
            time_remain=time_remaining_min(self._charge_ah, self._avg_current_a),
            switch_status=self._protection.switch_bits,
            charge_status=_CHARGING_STATUS if self._current_a > 0 else _DISCHARGE_STATUS,
            charge_mode=int(self._charge_mode),
            submodule=c.submodule,
        )
