"""The driver_base node's ROS parameters: names, defaults, validation (no ROS needed).

Every parameter is private (``~name``) and optional; ``lowerbase/driver/config/driver_base.yaml``
lists them all with their defaults and is what the launch file loads. ``load_settings`` turns
the node's private namespace (a plain dict, as ``rospy.get_param("~")`` returns it) into a
:class:`NodeSettings` and a :class:`~lowerbase.driver.core.DriverConfig`; a bad value raises
:class:`~lowerbase.errors.ConfigError` naming the parameter.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from lowerbase.driver.core import DriverConfig
from lowerbase.driver.ekf import EkfNoise
from lowerbase.driver.odometry import OdometryNoise
from lowerbase.errors import ConfigError, LowerbaseError

#: topic keys -> default names. Absolute and relative names as the vendor's interface has
#: them (relative ones resolve in the node's namespace); an empty name switches a topic off.
DEFAULT_TOPICS: dict[str, str] = {
    # published
    "odom_raw": "/odom_raw",  # nav_msgs/Odometry, encoders only
    "odom": "/odom",  # nav_msgs/Odometry, EKF (encoders + gyro)
    "imu": "/imu/data_raw",  # sensor_msgs/Imu, no orientation
    "odom_twist": "odom_twist",  # geometry_msgs/Twist, measured by the lower computer
    "odometer": "odometer",  # std_msgs/Float64 [m]
    "battery": "/battery",  # woosh_msgs/Battery
    "bms": "/driver_base/bms",  # woosh_msgs/BMS
    "parameter": "/driver_base/parameter",  # woosh_msgs/Parameter, latched
    "information": "/information",  # woosh_msgs/Information, latched
    "status_code": "status_code",  # std_msgs/UInt64
    "link_state": "~link_state",  # std_msgs/String, latched: waiting|configuring|ready|lost
    # subscribed
    "base_cmd_vel": "/base_cmd_vel",  # geometry_msgs/Twist, raw
    "smooth_cmd_vel": "/smooth_cmd_vel",  # geometry_msgs/Twist, smoothed by the lower computer
    "rgbled": "rgbled",  # woosh_msgs/LED, body strip (0)
    "rgbled_shelf": "rgbled_shelf",  # woosh_msgs/LED, shelf strip (1)
    # the same strip under the name the vendor's robot publishes it on
    "rgbled_shelf_vendor": "/kShelfLedColorPubName",  # woosh_msgs/LED, shelf strip (1)
}

#: rate keys -> default [Hz]. 0: every new sample from the lower computer (odometry 50 Hz,
#: IMU 100 Hz, odom_twist 50 Hz, odometer 10 Hz, status_code 10 Hz, battery and BMS 1 Hz:
#: the frame cycle times of chassis.dbc); > 0: at most that often.
DEFAULT_RATES: dict[str, float] = {
    "odom": 0.0,  # /odom_raw, /odom and the TF
    "imu": 0.0,
    "odom_twist": 0.0,
    "odometer": 0.0,
    "status_code": 0.0,
    "battery": 0.0,  # /battery and /driver_base/bms
}

#: DriverConfig fields that are plain floats/bools at the top level of the namespace
_DRIVER_SCALARS = ("command_rate", "command_timeout", "link_timeout", "request_retry",
                   "auto_enable", "malformed_log_period")


@dataclass(frozen=True)
class NodeSettings:
    """What the ROS layer itself needs (frames, topics, rates, covariances)."""

    odom_frame: str = "odom"  #: REP-105 odometry frame (header of /odom and /odom_raw)
    base_frame: str = "base_link"  #: REP-105 body frame (child of the odometry and the TF)
    imu_frame: str = "base_link"  #: the IMU's axes are the base's (chassis.dbc ImuGyro)
    publish_tf: bool = True  #: broadcast odom -> base_link from /odom (the EKF)
    topics: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_TOPICS))
    rates: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_RATES))
    #: [(rad/s)^2] per axis: the gyro's turn-on bias (0.5 deg/s 1-sigma) dominates its noise
    imu_angular_velocity_variance: float = 7.6e-5
    #: [(m/s^2)^2] per axis: the accelerometer's turn-on bias (20 mg 1-sigma)
    imu_linear_acceleration_variance: float = 0.04

    def __post_init__(self) -> None:
        for name in ("odom_frame", "base_frame", "imu_frame"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value or value.startswith("/"):
                raise ConfigError(f"~{name} must be a frame id without a leading '/', got "
                                  f"{value!r}")
        for name in ("imu_angular_velocity_variance",
                     "imu_linear_acceleration_variance"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"~covariance/{name} must be a finite number >= 0, got "
                                  f"{value!r}")


def _merge(kind: str, defaults: Mapping[str, Any], given: Any) -> dict[str, Any]:
    if given is None:
        return dict(defaults)
    if not isinstance(given, Mapping):
        raise ConfigError(f"~{kind} must be a dictionary, got {given!r}")
    unknown = sorted(set(given) - set(defaults))
    if unknown:
        raise ConfigError(f"~{kind}: unknown key(s) {', '.join(unknown)}; known: "
                          f"{', '.join(defaults)}")
    return {**defaults, **given}


def _noise(kind: str, cls: Any, given: Any) -> Any:
    names = [f.name for f in dataclasses.fields(cls)]
    values = _merge(kind, {n: getattr(cls(), n) for n in names}, given)
    try:
        return cls(**values)
    except (LowerbaseError, TypeError, ValueError) as exc:
        raise ConfigError(f"~{kind}: {exc}") from None


def load_settings(params: Mapping[str, Any]) -> tuple[NodeSettings, DriverConfig]:
    """Node settings and driver configuration from the node's private parameters."""
    known = {"odom_frame", "base_frame", "imu_frame", "publish_tf", "topics", "rates",
             "covariance", "odometry_noise", "ekf_noise", "gyro_sigma", *_DRIVER_SCALARS}
    unknown = sorted(set(params) - known)
    if unknown:
        raise ConfigError(f"unknown parameter(s) ~{', ~'.join(unknown)} (see "
                          "lowerbase/driver/config/driver_base.yaml)")
    topics = _merge("topics", DEFAULT_TOPICS, params.get("topics"))
    for key, name in topics.items():
        if not isinstance(name, str):
            raise ConfigError(f"~topics/{key} must be a string, got {name!r}")
    rates = _merge("rates", DEFAULT_RATES, params.get("rates"))
    for key, rate in rates.items():
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate >= 0):
            raise ConfigError(f"~rates/{key} must be a number >= 0 [Hz], got {rate!r}")
    cov = _merge("covariance", {
        "imu_angular_velocity_variance": 7.6e-5,
        "imu_linear_acceleration_variance": 0.04}, params.get("covariance"))
    publish_tf = params.get("publish_tf", True)
    if not isinstance(publish_tf, bool):
        raise ConfigError(f"~publish_tf must be true or false, got {publish_tf!r}")
    settings = NodeSettings(
        odom_frame=params.get("odom_frame", "odom"),
        base_frame=params.get("base_frame", "base_link"),
        imu_frame=params.get("imu_frame", "base_link"),
        publish_tf=publish_tf, topics=topics, rates={k: float(v) for k, v in rates.items()},
        **{k: float(v) for k, v in cov.items()},
    )
    driver: dict[str, Any] = {}
    for name in _DRIVER_SCALARS:
        if name in params:
            value = params[name]
            expected = bool if name == "auto_enable" else (int, float)
            if not isinstance(value, expected) or (expected is not bool
                                                   and isinstance(value, bool)):
                raise ConfigError(f"~{name} has the wrong type: {value!r}")
            driver[name] = value
    gyro_sigma = params.get("gyro_sigma", 0.0)
    if not (isinstance(gyro_sigma, (int, float)) and math.isfinite(gyro_sigma)
            and gyro_sigma >= 0):
        raise ConfigError(f"~gyro_sigma must be a number >= 0 [rad/s], got {gyro_sigma!r}")
    try:
        config = DriverConfig(
            **driver,
            odometry_noise=_noise("odometry_noise", OdometryNoise, params.get("odometry_noise")),
            ekf_noise=_noise("ekf_noise", EkfNoise, params.get("ekf_noise")),
            gyro_sigma=float(gyro_sigma) or None,
        )
    except ConfigError:
        raise
    except LowerbaseError as exc:
        raise ConfigError(f"~{exc}".replace("~driver ", "~")) from None
    return settings, config
