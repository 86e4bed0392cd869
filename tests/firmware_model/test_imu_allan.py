"""An Allan-deviation analysis of the IMU's output recovers the datasheet figures of the profile.

The data are what goes on the wire: samples quantised through the codec at the ImuGyro (1e-4
rad/s) and ImuAccel (1e-3 m/s^2) resolutions. With the default profile the white noise is
about 5 (gyro) and 7 (accel) LSB per sample, so quantisation adds under 0.4 % to the white
variance and does not dominate. The estimates, as IEEE 952 reads them: noise density on the
-1/2 slope at tau = 1 s, bias instability = the flat minimum / 0.664, rate random walk on the
+1/2 slope at tau = 3 s. An Allan deviation from T seconds of data at tau has a relative
spread of about sqrt(tau / T) per axis, hence the lengths of the runs below.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lowerbase.firmware_model.imu import DEG, DEG_PER_HOUR, MICRO_G, ImuModel
from lowerbase.firmware_model.profile import ImuParams, load_profile
from lowerbase.firmware_model.sim import SimRig
from lowerbase.protocol.codec import default_codec

RATE = 100.0  # [Hz] the default rate and the ImuGyro/ImuAccel cycle


def _through_codec(samples: np.ndarray) -> np.ndarray:
    """Samples (n, 6) as the upper side decodes them from ImuGyro + ImuAccel frames."""
    codec = default_codec()
    gyro, accel = codec.message("ImuGyro"), codec.message("ImuAccel")
    out = np.empty_like(samples)
    for k, row in enumerate(samples.tolist()):
        g = gyro.decode(gyro.encode({"X": row[0], "Y": row[1], "Z": row[2], "Counter": 0}))
        a = accel.decode(accel.encode({"X": row[3], "Y": row[4], "Z": row[5], "Counter": 0}))
        out[k] = (g["X"], g["Y"], g["Z"], a["X"], a["Y"], a["Z"])
    return out


def allan(y: np.ndarray, tau0: float) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of each column of ``y`` (n, axes), averaged over the axes
    (as variance), at half-octave taus up to a tenth of the record: (taus, adev)."""
    n = len(y)
    ms = np.unique(np.round(2.0 ** np.arange(0.0, math.log2(n / 10), 0.5)).astype(int))
    theta = np.vstack([np.zeros((1, y.shape[1])), np.cumsum(y - y.mean(axis=0), axis=0)])
    avar = []
    for m in ms:
        d = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
        avar.append(np.mean(d * d) / (2.0 * m * m))
    return ms * tau0, np.sqrt(np.array(avar))


def noise_density(taus: np.ndarray, adev: np.ndarray) -> float:
    """The -1/2 slope line through the short taus (white dominated), read at tau = 1 s."""
    sel = (taus >= 0.05) & (taus <= 0.5)
    return float(np.exp(np.mean(np.log(adev[sel] * np.sqrt(taus[sel])))))


def bias_instability(taus: np.ndarray, adev: np.ndarray, record: float) -> float:
    """The flat minimum (taus from 1 s to a twentieth of the record) / 0.664."""
    sel = (taus >= 1.0) & (taus <= record / 20)
    return float(adev[sel].min() / 0.664)


def random_walk(taus: np.ndarray, adev: np.ndarray, lo: float, hi: float) -> float:
    """The +1/2 slope line through taus in [lo, hi], read at tau = 3 s: K."""
    sel = (taus >= lo) & (taus <= hi)
    return float(np.exp(np.mean(np.log(adev[sel] / np.sqrt(taus[sel] / 3.0)))))


def _quantised(samples: np.ndarray) -> np.ndarray:
    """The codec's quantisation, vectorised (checked equal to the codec on a prefix)."""
    codec = default_codec()
    scale = np.array([codec.message("ImuGyro").signal("X").scale] * 3
                     + [codec.message("ImuAccel").signal("X").scale] * 3)
    out = np.round(samples / scale) * scale
    np.testing.assert_allclose(out[:2000], _through_codec(samples[:2000]), atol=1e-12)
    return out


def test_allan_analysis_recovers_noise_density_and_bias_instability() -> None:
    p = ImuParams()
    hours = 4.0
    data = _quantised(ImuModel(p).at_rest(int(hours * 3600 * RATE), 1.0 / RATE))
    for cols, density, instability in (
        (slice(0, 3), p.gyro_noise_density * DEG, p.gyro_bias_instability * DEG_PER_HOUR),
        (slice(3, 6), p.accel_noise_density * MICRO_G, p.accel_bias_instability * MICRO_G),
    ):
        taus, adev = allan(data[:, cols], 1.0 / RATE)
        assert noise_density(taus, adev) == pytest.approx(density, rel=0.1)
        assert bias_instability(taus, adev, hours * 3600) == pytest.approx(instability, rel=0.1)


def test_allan_analysis_recovers_the_rate_random_walk() -> None:
    """A profile whose random walk shows within the record (no flicker): K on the +1/2 line."""
    p = ImuParams(gyro_bias_instability=0.0, accel_bias_instability=0.0,
                  gyro_random_walk=2e-5, accel_random_walk=4e-4, bias_walk_bound=100.0)
    hours = 2.0
    data = _quantised(ImuModel(p).at_rest(int(hours * 3600 * RATE), 1.0 / RATE))
    for cols, walk in ((slice(0, 3), p.gyro_random_walk), (slice(3, 6), p.accel_random_walk)):
        taus, adev = allan(data[:, cols], 1.0 / RATE)
        assert random_walk(taus, adev, 30.0, 360.0) == pytest.approx(walk, rel=0.1)


def test_the_frames_the_mcu_emits_carry_the_noise_density() -> None:
    """Ten minutes at rest on the simulated clock, analysed from the decoded frames."""
    profile = load_profile()
    rig = SimRig(profile, keep=False)
    codec = default_codec()
    ids = {codec.message(n).frame_id: n for n in ("ImuGyro", "ImuAccel")}
    rows: dict[str, list[tuple[float, float, float]]] = {"ImuGyro": [], "ImuAccel": []}

    def on_send(frame_id: int, data: bytes) -> None:
        name = ids.get(frame_id)
        if name is not None:
            v = codec.message(name).decode(data)
            rows[name].append((float(v["X"]), float(v["Y"]), float(v["Z"])))

    rig.mcu._send = on_send  # the rig's own log is off; watch the wire instead
    rig.run(600.0)
    n = min(len(rows["ImuGyro"]), len(rows["ImuAccel"]))
    assert n >= 600 * RATE - 2
    data = np.hstack([np.array(rows["ImuGyro"][:n]), np.array(rows["ImuAccel"][:n])])
    imu = dataclasses.replace(profile.imu)
    taus, adev = allan(data[:, :3], 1.0 / RATE)
    assert noise_density(taus, adev) == pytest.approx(imu.gyro_noise_density * DEG, rel=0.1)
    taus, adev = allan(data[:, 3:], 1.0 / RATE)
    assert noise_density(taus, adev) == pytest.approx(imu.accel_noise_density * MICRO_G, rel=0.1)
