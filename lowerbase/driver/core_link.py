"""The link's life cycle in :class:`~lowerbase.driver.core.DriverCore`: Heartbeats (first
contact, the Uptime timeline, a reboot suspected then confirmed), reading the parameters
(configuring), enabling CAN control (see core's module docstring)."""

from __future__ import annotations

import logging
import math
from typing import Any

from lowerbase.clock import Clock
from lowerbase.driver.core_defs import ODOMETRY_PARAMETERS, UPTIME_SLACK, LinkState, _continues
from lowerbase.driver.core_odom import OdometryInput
from lowerbase.driver.odometry import OdometryParameters, WheelOdometry
from lowerbase.transport.peers import PeerMonitor

log = logging.getLogger("lowerbase.driver.core")


class LinkLifecycle(OdometryInput):
    """DriverCore's Heartbeat, parameter and enable handling (a mixin)."""

    clock: Clock
    peers: PeerMonitor
    boot_counter: int | None
    reboots: int
    operator_hold: bool
    uptime_slack: float
    versions: dict[str, str]
    _param_names: Any
    _uptime: tuple[float, float] | None
    _reboot_suspect: tuple[float, float, int] | None
    _overruns: int
    _configured_ok: bool
    _enable_wanted: bool
    _last_enable: float
    _last_heartbeat: float
    _last_request: float
    _version_parts: dict[int, dict[int, bytes]]

    def _settle(self) -> None:
        raise NotImplementedError

    def control(self, command: str) -> None:
        raise NotImplementedError

    def _on_Heartbeat(self, v: dict[str, Any], now: float) -> None:
        self._last_heartbeat = now
        boot, uptime = int(v["BootCounter"]), float(v["Uptime"])
        overruns = int(v.get("Overruns", 0))
        slipped, self._overruns = (overruns - self._overruns) % 16, overruns
        if self.boot_counter is None or self._uptime is None:
            self.boot_counter, self._uptime = boot, (uptime, now)
            self._enable_wanted = self.config.auto_enable
            self._configure("first contact")
            return
        if boot == self.boot_counter:  # every slip it counted (a reboot restarts the count)
            self.stats["lower_computer_overruns"] += slipped
        if _continues(self._uptime, uptime, now, self.uptime_slack):
            self._uptime = (uptime, now)
            if self._reboot_suspect is not None:
                self._reboot_suspect = None
                self.stats["heartbeat_inconsistent"] += 1
            if boot != self.boot_counter:
                self.stats["heartbeat_inconsistent"] += 1
                log.warning("a Heartbeat with BootCounter %d (not %d) but the Uptime still "
                            "counting: not a reboot, ignored (garbled or forged?)", boot,
                            self.boot_counter)
            return
        if slipped and boot == self.boot_counter and uptime > self._uptime[0]:
            # the lower computer fell behind real time and says so (its Overruns moved): its
            # time slipped, the same boot goes on; follow its timeline from here
            gap = self._uptime[0] + (now - self._uptime[1]) - uptime
            self._uptime = (uptime, now)
            self._reboot_suspect = None
            self.stats["lower_computer_slips"] += slipped
            log.warning("the lower computer fell behind real time (Overruns +%d): its Uptime "
                        "is %.3f s behind this clock's; following it", slipped, gap)
            return
        suspect = self._reboot_suspect
        if suspect is not None and _continues(suspect[:2], uptime, now, self.uptime_slack) \
                and boot == suspect[2]:
            behind = uptime < self._uptime[0] + (now - self._uptime[1])
            self._reboot_suspect = None
            self.boot_counter, self._uptime = boot, (uptime, now)
            if behind:
                self.reboots += 1
                log.warning("the lower computer rebooted (boot #%d, up %.1f s): reading "
                            "parameters again%s", boot, uptime, "; kept in standby (the "
                            "operator's hold: call ~enable)" if self.operator_hold else "")
                self._enable_wanted = self.config.auto_enable and not self.operator_hold
                self._configure("reboot")
            else:  # ahead of the old timeline: not a reboot; follow the new one
                self.stats["heartbeat_timeline_jump"] += 1
                log.warning("the lower computer's Uptime jumped ahead to %.1f s", uptime)
            return
        self._reboot_suspect = (uptime, now, boot)
        self.stats["heartbeat_off_timeline"] += 1
        self._hold_odometry(0.0)  # counters may restart: the next sample is a baseline

    def allow_receive_lag(self, seconds: float) -> None:
        """Take Heartbeats handled up to ``seconds`` late on this core's clock for the same
        lower computer (not a reboot, a jump or a second one). For ROS sim time: at K x real
        time a backlog of frames 1/K as long puts their Uptime that far behind /clock."""
        self.uptime_slack = max(UPTIME_SLACK, seconds)
        self.peers.tolerance = max(self.peers.tolerance, seconds)

    def _configure(self, why: str) -> None:
        self.state = LinkState.CONFIGURING
        self._configured_ok = False
        self.parameters = {}
        self.versions = {}
        self._version_parts = {}
        self._wheels = {}
        if self.odometry is not None:
            self.odometry.reset_baseline()  # counters restart at 0 after a reboot
        self._last_request = -math.inf
        self._notify("configuring")
        log.info("configuring (%s)", why)

    def _on_ParameterResponse(self, v: dict[str, Any], now: float) -> None:
        name = self._param_names.get(int(v["Index"]))
        if name is None:
            return
        if int(v["Result"]) != 0:
            self.stats["parameter_nack"] += 1
            log.warning("parameter %s: nack %d", name, int(v["Result"]))
        self.parameters[name] = float(v["Value"])
        if self.state == LinkState.CONFIGURING and set(self._param_names.values()) <= set(
            self.parameters
        ):
            self._configured()
        elif self.state == LinkState.READY:
            self._apply_parameters()
        self._notify("parameters")

    def _configured(self) -> None:
        self._apply_parameters()
        self._configured_ok = True
        log.info("lower computer configured: %s", ", ".join(
            f"{k}={self.parameters[k]:g}" for k in ODOMETRY_PARAMETERS))
        if self._enable_wanted:
            self._enable()
        self._notify("ready")  # configured (the link state says whether commands are taken)
        self._settle()

    def _enable(self) -> None:
        self._last_enable = self.clock.now()
        self.control("EnableCanControl")

    def _apply_parameters(self) -> None:
        params = OdometryParameters.from_lower_computer(self.parameters)
        # a count jump faster than the drive train can turn is a counter reset, not motion
        top_rpm = self.parameters.get("maxRPM", 3000.0)
        ratio = min(params.ratio_left, params.ratio_right)
        max_wheel_speed = 1.5 * top_rpm / 60.0 / ratio * params.wheel_perimeter
        if self.odometry is None:
            self.odometry = WheelOdometry(params, self.config.odometry_noise,
                                          max_wheel_speed=max_wheel_speed)
        else:
            self.odometry.max_wheel_speed = max_wheel_speed
            if self.odometry.params != params:
                self.odometry.params = params
                self.odometry.reset_baseline()
