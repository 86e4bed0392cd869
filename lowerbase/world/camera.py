"""A pinhole depth camera on the base, rendered against a 2.5D world with numpy.

The world is the floor plane z = 0, the map's occupied cells extruded from the floor to the scene's
wall height, and the obstacles (prisms to their heights). Every pixel's ray is parametrised by its
depth Z (the optical-axis coordinate, what a depth image stores): floor and obstacles are hit
analytically; walls through the map: the horizontal directions of all pixels are binned finely
(a bin spans at most half a cell at the farthest reach), one exact grid ray is cast per bin
(:func:`raycast.cast_grid`), and each pixel intersects its own ray with the cell face that its
bin hit, so flat walls are exact and only wall corners can be off, by less than half a cell.

Outputs follow a RealSense under realsense2_camera: ``depth`` 16UC1 in millimetres (0 = no
depth), ``color`` rgb8 of the same intrinsics (aligned; plain shading), ``points`` in the optical
frame (REP-103 optical: x right, y down, z forward) and ``points_without_planes`` (the floor
removed: points higher than ``ground_threshold`` above the floor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lowerbase.errors import ConfigError, WorldError
from lowerbase.world.raycast import FACE_X, Scene, Solid, cast_grid


@dataclass(frozen=True)
class CameraConfig:
    """Intrinsics [px], mounting pose on base_link ([m], yaw/pitch [rad]; pitch > 0 looks
    down), depth range [m] and the stereo noise model sigma(Z) = Z^2 * subpixel / (fx * B)."""

    name: str = "camera_1"
    frame_id: str = "camera_1_link"
    optical_frame_id: str = "camera_1_depth_optical_frame"
    width: int = 640
    height: int = 480
    fx: float = 385.0
    fy: float = 385.0
    cx: float = 319.5
    cy: float = 239.5
    x: float = 0.35
    y: float = 0.0
    z: float = 0.30
    yaw: float = 0.0
    pitch: float = math.radians(20.0)
    min_range: float = 0.105
    max_range: float = 10.0
    rate_hz: float = 15.0
    baseline: float = 0.050        # [m] stereo baseline
    subpixel: float = 0.08         # [px] RMS disparity error; 0 = no noise
    ground_threshold: float = 0.05  # [m] cloud_without_planes keeps points above this height
    seed: int = 3

    def __post_init__(self) -> None:
        def bad(key: str, allowed: str) -> ConfigError:
            return ConfigError(f"camera {self.name!r}: {key} = {getattr(self, key)!r} is "
                               f"invalid; allowed: {allowed}")

        for key in ("width", "height"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 8192:
                raise bad(key, "an integer 1..8192")
        checks = {"fx": (1e-3, 1e6), "fy": (1e-3, 1e6), "cx": (-1e4, 1e4), "cy": (-1e4, 1e4),
                  "x": (-100, 100), "y": (-100, 100), "z": (0.0, 10.0),
                  "yaw": (-2 * math.pi, 2 * math.pi), "pitch": (-math.pi / 2, math.pi / 2),
                  "min_range": (0.0, 100.0), "max_range": (self.min_range, 1000.0),
                  "rate_hz": (1e-3, 1000.0), "baseline": (1e-4, 10.0), "subpixel": (0.0, 10.0),
                  "ground_threshold": (0.0, 10.0)}
        for key, (lo, hi) in checks.items():
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise bad(key, f"{lo:g}..{hi:g}")
        if self.max_range <= self.min_range:
            raise bad("max_range", f"> min_range ({self.min_range:g} m)")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise bad("seed", "an integer >= 0")
        if not (self.name and self.frame_id and self.optical_frame_id):
            raise ConfigError("camera name, frame_id and optical_frame_id must be non-empty")

    def depth_sigma(self, depth: np.ndarray) -> np.ndarray:
        """RMS depth error [m] at depth Z [m] (quadratic in Z)."""
        return depth * depth * self.subpixel / (self.fx * self.baseline)

    def optical_to_base(self) -> np.ndarray:
        """3x3 rotation taking optical-frame vectors into base_link."""
        optical_to_link = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        cy, sy, cp, sp = math.cos(self.yaw), math.sin(self.yaw), math.cos(self.pitch), \
            math.sin(self.pitch)
        rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
        return rz @ ry @ optical_to_link


@dataclass(frozen=True)
class CameraFrame:
    stamp: float
    color: np.ndarray        # (h, w, 3) uint8 rgb8
    depth: np.ndarray        # (h, w) uint16 [mm], 0 = no depth (16UC1)
    points: np.ndarray       # (n, 3) float32 [m], optical frame
    points_without_planes: np.ndarray  # (m, 3) float32 [m], optical frame, floor removed


_SKY, _FLOOR, _WALL_X, _WALL_Y, _SOLID = 0, 1, 2, 3, 4


class DepthCamera:
    """Renders :class:`CameraFrame` s; noise from its own seeded generator."""

    def __init__(self, config: CameraConfig) -> None:
        self.config = config
        self.rng = np.random.default_rng(config.seed)
        # Optical-frame ray of each column / row per metre of depth: ((u-cx)/fx, (v-cy)/fy, 1).
        self._xo = ((np.arange(config.width) - config.cx) / config.fx).astype(np.float32)
        self._yo = ((np.arange(config.height) - config.cy) / config.fy).astype(np.float32)

    def render(self, scene: Scene, pose: tuple[float, float, float], stamp: float
               ) -> CameraFrame:
        cfg = self.config
        if cfg.z >= scene.wall_height:
            raise WorldError(f"camera {cfg.name!r} at z = {cfg.z:g} m is not below the wall "
                             f"height {scene.wall_height:g} m; mount it lower")
        bx, by, bt = pose
        c, s = math.cos(bt), math.sin(bt)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ cfg.optical_to_base()
        cam = np.array([bx + c * cfg.x - s * cfg.y, by + s * cfg.x + c * cfg.y, cfg.z])
        yaw = bt + cfg.yaw
        # Map-frame displacement per metre of depth, and the same in a frame turned by the
        # camera's heading (for bearings relative to it), each (h*w,) float32.
        cy_, sy_ = math.cos(yaw), math.sin(yaw)
        heading = np.array([[cy_, sy_, 0.0], [-sy_, cy_, 0.0], [0.0, 0.0, 1.0]]) @ rot
        d = [self._component(rot[k]) for k in range(3)]
        fwd, left = self._component(heading[0]), self._component(heading[1])
        n = d[0].size
        down = d[2] < -1e-9
        with np.errstate(divide="ignore"):
            depth = np.where(down, np.float32(-cam[2]) / np.where(down, d[2], -1.0),
                             np.float32(np.inf)).astype(np.float32)
        kind = down.astype(np.int8)  # _FLOOR where down, else _SKY
        horiz = np.sqrt(fwd * fwd + left * left)
        rel = np.arctan2(left, fwd)
        self._walls(scene, cam, d, horiz, rel, yaw, depth, kind)
        for i, solid in enumerate(scene.solids):
            rows = _in_view(solid, cam, rel, yaw)
            if rows.size == 0:
                continue
            z_hit = _solid_depth(solid, cam, np.stack([d[0][rows], d[1][rows], d[2][rows]], 1))
            closer = z_hit < depth[rows]
            depth[rows[closer]] = z_hit[closer]
            kind[rows[closer]] = _SOLID + i
        valid = (depth >= cfg.min_range) & (depth <= cfg.max_range)
        true = np.where(valid, depth, np.float32(0.0))
        noise = self.rng.standard_normal(n, dtype=np.float32)
        noisy = true + true * true * np.float32(cfg.subpixel / (cfg.fx * cfg.baseline)) * noise
        noisy = np.clip(noisy, cfg.min_range, cfg.max_range)
        depth_mm = np.where(valid, np.round(noisy * 1000.0), 0.0).astype(np.uint16)
        h, w = cfg.height, cfg.width
        z = depth_mm.reshape(h, w).astype(np.float32) * np.float32(0.001)
        keep = (depth_mm > 0).reshape(h, w)
        cloud = np.stack([self._xo[None, :] * z, self._yo[:, None] * z, z], axis=-1)[keep]
        height = (cam[2] + z * d[2].reshape(h, w))[keep]
        color = _shade(kind, np.where(valid, depth, np.float32(np.inf)), cam, d)
        return CameraFrame(stamp, color.reshape(h, w, 3), depth_mm.reshape(h, w), cloud,
                           cloud[height > cfg.ground_threshold])

    def _component(self, row: np.ndarray) -> np.ndarray:
        """row . (xo, yo, 1) for every pixel, as a flat float32 array (row-major image)."""
        return (np.float32(row[0]) * self._xo[None, :] + np.float32(row[1]) * self._yo[:, None]
                + np.float32(row[2])).ravel()

    def _walls(self, scene: Scene, cam: np.ndarray, d: list[np.ndarray], horiz: np.ndarray,
               rel: np.ndarray, yaw: float, depth: np.ndarray, kind: np.ndarray) -> None:
        cfg = self.config
        moving = horiz > 1e-9
        if not moving.any():
            return
        reach = cfg.max_range * float(horiz[moving].max())
        step = max(min(scene.grid.resolution / (2.0 * reach), 0.01), 1e-4)
        lo, hi = float(rel[moving].min()), float(rel[moving].max())
        bins = np.arange(math.ceil((hi - lo) / step) + 1)
        hits = cast_grid(scene.mask, scene.grid, cam[0], cam[1], yaw + lo + bins * step, reach,
                         scene.grid_field)
        # Per bin: the face hit (x = const or y = const) as an offset from the camera.
        is_x = hits.face == FACE_X
        offset = np.where(is_x, hits.face_coord - cam[0], hits.face_coord - cam[1])
        offset = np.where(hits.face == 0, np.nan, offset).astype(np.float32)
        b = np.rint((rel - np.float32(lo)) * np.float32(1.0 / step)).astype(np.int32)
        np.clip(b, 0, bins.size - 1, out=b)
        with np.errstate(divide="ignore", invalid="ignore"):
            z_wall = offset[b] / np.where(is_x[b], d[0], d[1])
            z_bin = hits.distance.astype(np.float32)[b] / horiz
        z_wall = np.where(z_wall > 0, z_wall, z_bin)      # NaN (no face) -> the bin's distance
        elevation = cam[2] + z_wall * d[2]
        hit = (elevation >= 0) & (elevation <= scene.wall_height) & (z_wall < depth) & moving
        depth[hit] = z_wall[hit]
        kind[hit] = np.where(is_x[b[hit]], _WALL_X, _WALL_Y)


def _in_view(solid: Solid, cam: np.ndarray, rel: np.ndarray, yaw: float) -> np.ndarray:
    """Indices of the pixels whose bearing can meet the solid (its bounding circle's span)."""
    if solid.circle is not None:
        ccx, ccy, radius = solid.circle
    else:
        assert solid.polygon is not None
        ccx, ccy = solid.polygon.mean(axis=0)
        radius = float(np.hypot(solid.polygon[:, 0] - ccx, solid.polygon[:, 1] - ccy).max())
    dist = math.hypot(ccx - cam[0], ccy - cam[1])
    if dist <= radius * 1.0001:
        return np.arange(rel.size)
    centre = math.remainder(math.atan2(ccy - cam[1], ccx - cam[0]) - yaw, 2 * math.pi)
    half = math.asin(radius / dist) + 1e-3
    off = np.abs(rel - np.float32(centre))
    return np.flatnonzero(np.minimum(off, 2 * math.pi - off) <= half)


def _solid_depth(solid: Solid, cam: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Depth at which each ray first meets the solid's sides or top (inf: never)."""
    px, py, pz = cam
    best = np.full(d.shape[0], np.inf)
    dx, dy, dz = d[:, 0:1], d[:, 1:2], d[:, 2:3]
    if solid.polygon is not None:
        seg = solid.segments()
        ax, ay, ex, ey = seg[:, 0], seg[:, 1], seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
        den = dx * ey - dy * ex
        wx, wy = ax - px, ay - py
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (wx * ey - wy * ex) / den
            u = (wx * dy - wy * dx) / den
        zt = pz + t * dz
        ok = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1) & (zt >= 0) & \
            (zt <= solid.height)
        best = np.where(ok, t, np.inf).min(axis=1)
    else:
        assert solid.circle is not None
        ccx, ccy, r = solid.circle
        ox, oy = px - ccx, py - ccy
        a = dx[:, 0] ** 2 + dy[:, 0] ** 2
        bq = ox * dx[:, 0] + oy * dy[:, 0]
        disc = bq * bq - a * (ox * ox + oy * oy - r * r)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-bq - np.sqrt(np.maximum(disc, 0.0))) / a
        zt = pz + t1 * dz[:, 0]
        ok = (disc >= 0) & (a > 1e-18) & (t1 > 0) & (zt >= 0) & (zt <= solid.height)
        best = np.where(ok, t1, np.inf)
    if pz > solid.height:   # the top face, seen from above
        with np.errstate(divide="ignore", invalid="ignore"):
            t_top = (solid.height - pz) / dz[:, 0]
        qx, qy = px + t_top * dx[:, 0], py + t_top * dy[:, 0]
        inside = _inside(solid, qx, qy) & (dz[:, 0] < 0)
        best = np.where(inside & (t_top < best), t_top, best)
    return best


def _inside(solid: Solid, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
    if solid.circle is not None:
        ccx, ccy, r = solid.circle
        return (qx - ccx) ** 2 + (qy - ccy) ** 2 <= r * r
    assert solid.polygon is not None
    poly = solid.polygon
    x1, y1 = poly[:, 0], poly[:, 1]
    x2, y2 = np.roll(x1, -1), np.roll(y1, -1)
    qx2, qy2 = qx[:, None], qy[:, None]
    crosses = (y1 > qy2) != (y2 > qy2)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x1 + (qy2 - y1) * (x2 - x1) / (y2 - y1)
    return np.asarray((crosses & (qx2 < xi)).sum(axis=1) % 2 == 1)


_PALETTE = np.array([[40, 40, 48], [150, 150, 150], [200, 180, 140], [170, 150, 115],
                     [200, 60, 50], [60, 120, 200], [80, 170, 80], [220, 170, 40]],
                    dtype=np.float32)


def _shade(kind: np.ndarray, depth: np.ndarray, cam: np.ndarray, d: list[np.ndarray]
           ) -> np.ndarray:
    """Flat colours by surface, a 0.5 m checkerboard on the floor, darker with distance."""
    k = np.where(kind >= _SOLID, _SOLID + (kind - _SOLID) % (len(_PALETTE) - _SOLID), kind)
    z = np.where(np.isfinite(depth), depth, np.float32(0.0))
    cell = np.floor((cam[0] + z * d[0]) * 2.0) + np.floor((cam[1] + z * d[1]) * 2.0)
    dark = (kind == _FLOOR) & (cell % 2 == 1)
    gain = np.where(dark, np.float32(0.75), np.float32(1.0)) / (1.0 + np.float32(0.08) * z)
    return (_PALETTE[k] * gain[:, None]).astype(np.uint8)
