"""The profile's [sensors] section: defaults, parsing in degrees, one-line errors, mounts."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from lowerbase.errors import ConfigError, WorldError
from lowerbase.firmware_model.profile import Profile, load_profile
from lowerbase.world.lidar import LidarRig
from lowerbase.world.sensors import SensorsConfig, sensors_from_dict, sensors_from_profile_file


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_default_profile_sensors_equal_the_dataclass_defaults() -> None:
    config = sensors_from_profile_file()
    assert config == SensorsConfig()
    assert [lc.beams for lc in config.lidars] == [1651, 1651]
    assert config.lidars[0].angular_step == pytest.approx(0.002909, abs=1e-6)
    assert config.camera is not None and config.camera.pitch == pytest.approx(math.radians(20))
    rig = LidarRig(config.lidars, config.scan)
    assert rig.rate_hz == 25.0
    assert load_profile() == Profile()   # the chassis profile ignores [sensors]


def test_sections_in_degrees_and_camera_disabled(tmp_path: Path) -> None:
    path = write(tmp_path, """
[chassis]
max_linear = 0.9
[sensors.scan]
beams = 360
[[sensors.lidar]]
name = "only"
x = 0.1
yaw_deg = 90.0
fov_deg = 360.0
angular_step_deg = 0.5
[sensors.camera]
enabled = false
""")
    config = sensors_from_profile_file(path)
    assert load_profile(path).chassis.max_linear == 0.9
    (only,) = config.lidars
    assert only.yaw == pytest.approx(math.pi / 2) and only.beams == 720
    assert config.scan.beams == 360 and config.camera is None


@pytest.mark.parametrize(("text", "message"), [
    ("[sensors]\nlidars = []\n", r"unknown key sensors.lidars; did you mean sensors.lidar\?"),
    ("[[sensors.lidar]]\nfov = 3.0\n", r"unknown key sensors.lidar\[0\].fov; did you mean "
                                       r"sensors.lidar\[0\].fov_deg\?"),
    ("[[sensors.lidar]]\nrange_max = -1.0\n", r"lidar 'front': range_max = -1.0 is invalid"),
    ("[[sensors.lidar]]\nyaw_deg = 'north'\n", r"sensors.lidar\[0\].yaw_deg = 'north' is not"),
    ("[[sensors.lidar]]\n[[sensors.lidar]]\n", r"names must be unique"),
    ("[sensors.camera]\nwidth = 64.5\n", r"width = 64.5 is invalid; allowed: an integer"),
    ("[sensors.camera]\nenabled = 1\n", r"enabled = 1 must be true or false"),
    ("[sensors.scan]\nbeams = 0\n", r"scan.beams = 0 is invalid"),
])
def test_bad_sensors_are_one_config_error_naming_the_file(tmp_path: Path, text: str,
                                                          message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=message) as info:
        sensors_from_profile_file(path)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


def test_a_sensor_outside_the_footprint_is_one_world_error(tmp_path: Path) -> None:
    on_corner = write(tmp_path, "[[sensors.lidar]]\nx = 0.4\ny = 0.25\n")
    assert sensors_from_profile_file(on_corner).lidars[0].x == 0.4   # on the edge: on the base
    outside = write(tmp_path, "[[sensors.lidar]]\nname = 'mast'\nx = 0.45\n")
    with pytest.raises(WorldError, match=r"lidar 'mast' at \(0.45, 0\) m is outside the "
                                         r"robot's footprint; mount it on the base") as info:
        sensors_from_profile_file(outside)
    assert "\n" not in str(info.value)
    camera = write(tmp_path, "[sensors.camera]\ny = -0.31\n")
    with pytest.raises(WorldError, match=r"camera 'camera_1' at \(0.35, -0.31\) m is outside"):
        sensors_from_profile_file(camera)
    # Unknown profile sections are still refused by the chassis profile.
    with pytest.raises(ConfigError, match=r"unknown section sensor; did you mean sensors\?"):
        load_profile(write(tmp_path, "[sensor]\n"))


def test_sensors_from_dict_reports_its_source() -> None:
    with pytest.raises(ConfigError, match=r"^scenario.toml: unknown key sensors.radar"):
        sensors_from_dict({"radar": {}}, source="scenario.toml")
