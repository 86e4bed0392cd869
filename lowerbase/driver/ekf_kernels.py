"""Compiled (numba) arithmetic of the planar EKF's wheel cycle (:mod:`lowerbase.driver.ekf`).

Per 20 ms wheel cycle the filter makes two small measurement updates and drives the pose over
the cycle. In numpy that was some 40 calls on 6x6 and smaller arrays (about 1 us each, more
than the arithmetic); here it is two kernel calls, on the filter's own arrays (``kf.x``
(6, 1) and ``kf.P`` (6, 6), float64), in place.

The arithmetic is what :func:`lowerbase.driver.ekf_model.innovation`,
:func:`~lowerbase.driver.ekf_model.apply_update`, :func:`~lowerbase.driver.ekf_model.motion_model`,
:func:`~lowerbase.driver.ekf_model.motion_jacobian` and
:func:`~lowerbase.driver.ekf_model.slip_noise` do (tests/driver/test_ekf_kernels.py pins it to
them), with every product summed in index order: numba without fastmath neither reorders nor
fuses the operations, so the results do not depend on the CPU. numpy's ``@`` goes through
OpenBLAS, whose kernels (chosen per CPU at run time) fuse multiply-adds; the last bits of the
two differ (relative 1e-16 per operation), not the filter.

Compiled on first use and cached by :func:`lowerbase.jit.compiled`.
"""

from __future__ import annotations

import math

import numpy as np

from lowerbase.jit import compiled

_jit = compiled()
_inlined = compiled(inline="always")  # the product helpers: inlined in numba's IR

# state indices (as lowerbase.driver.ekf_model's; repeated: numba reads module globals as
# compile-time constants, and this module must not import the model's numpy objects)
_X, _Y, _YAW, _V, _W, _B = 0, 1, 2, 3, 4, 5


@_inlined
def _product(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out <- a @ b``, each entry summed in index order from 0.0 (no reordering, no fused
    multiply-add: the same bits on every CPU)."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@_inlined
def _product_t(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out <- a @ b^T``, summed as :func:`_product` sums."""
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * b[j, k]
            out[i, j] = acc


@_jit
def measure(
    x: np.ndarray, p: np.ndarray, h: np.ndarray, z: np.ndarray, r: np.ndarray,
    keep: np.ndarray, gated: bool, gate: float,
    y: np.ndarray, s: np.ndarray, si: np.ndarray, gain: np.ndarray,
) -> tuple[float, bool]:
    """Innovation of ``z = H x + noise(R)`` (1-D or 2-D) and, unless ``gated`` and its
    Mahalanobis^2 is not ``<= gate``, the Kalman update of ``x`` and ``p`` in place with the
    gain's rows zeroed where ``keep`` is 0 (consider states; their block of ``p`` stays).

    Writes ``y`` (m, 1), ``S`` and ``S^-1`` (m, m) and the gain ``K`` (n, m; zero when not
    applied); returns ``(d2, applied)`` (arrays made here would cost more to hand back to
    Python than the whole update)."""
    n = x.shape[0]
    m = h.shape[0]
    pht = np.empty((n, m))
    _product_t(p, h, pht)
    _product(h, pht, s)
    _product(h, x, y)
    for i in range(m):
        for j in range(m):
            s[i, j] = s[i, j] + r[i, j]
        y[i, 0] = z[i, 0] - y[i, 0]
    if m == 1:
        si[0, 0] = 1.0 / s[0, 0]
        d2 = y[0, 0] ** 2 * si[0, 0]
    else:
        a, b, c, d = s[0, 0], s[0, 1], s[1, 0], s[1, 1]
        det = a * d - b * c
        si[0, 0], si[0, 1], si[1, 0], si[1, 1] = d / det, -b / det, -c / det, a / det
        y0, y1 = y[0, 0], y[1, 0]
        d2 = (y0 * (d * y0 - b * y1) + y1 * (a * y1 - c * y0)) / det
    if gated and not d2 <= gate:
        gain[:, :] = 0.0
        return d2, False
    _product(pht, si, gain)  # the optimal gain P H^T S^-1
    cov = np.empty((n, n))  # C = K_opt (P H^T)^T, before the consider rows are zeroed
    _product_t(gain, pht, cov)
    for i in range(n):
        if keep[i] == 0:
            for j in range(m):
                gain[i, j] = 0.0
            for j in range(n):
                if keep[j] == 0:
                    cov[i, j] = 0.0  # the consider x consider block keeps its P
    dx = pht[:, :1]  # (P H^T is used up)
    _product(gain, y, dx)
    for i in range(n):
        x[i, 0] = x[i, 0] + dx[i, 0]
    _subtract_symmetric(p, cov)
    return d2, True


@_jit
def _subtract_symmetric(p: np.ndarray, c: np.ndarray) -> None:
    """``p <- (q + q^T) / 2`` with ``q = p - c``."""
    n = p.shape[0]
    for i in range(n):
        for j in range(i, n):
            v = 0.5 * ((p[i, j] - c[i, j]) + (p[j, i] - c[j, i]))
            p[i, j] = v
            p[j, i] = v


@_jit
def drive(x: np.ndarray, p: np.ndarray, dt: float, max_step: float, frozen: bool,
          lateral_slip_sq: float) -> None:
    """Drive the pose of ``x`` over ``dt`` [s] with its rates, in steps of at most ``max_step``
    (midpoint position step); unless ``frozen``, ``p <- F p F^T + Q_slip`` per step (the
    sideways-slip noise ``lateral_slip_sq * h * n n^T`` across the heading); then ``p``
    symmetrised. In place."""
    steps = max(1, math.ceil(dt / max_step))
    h = dt / steps
    n = x.shape[0]
    f = np.eye(n)
    fp = np.empty((n, n))
    q = np.zeros((n, n))
    for _ in range(steps):
        v, w, yaw = x[_V, 0], x[_W, 0], x[_YAW, 0]
        mid = yaw + 0.5 * w * h
        c, s = math.cos(mid), math.sin(mid)
        if not frozen:
            f[_X, _YAW] = -v * h * s
            f[_X, _V] = h * c
            f[_X, _W] = -v * h * s * 0.5 * h
            f[_Y, _YAW] = v * h * c
            f[_Y, _V] = h * s
            f[_Y, _W] = v * h * c * 0.5 * h
            f[_YAW, _W] = h
            _product(f, p, fp)
            scale = lateral_slip_sq * h
            nx, ny = -math.sin(yaw), math.cos(yaw)
            q[_X, _X], q[_X, _Y] = scale * (nx * nx), scale * (nx * ny)
            q[_Y, _X], q[_Y, _Y] = scale * (ny * nx), scale * (ny * ny)
            _product_t(fp, f, p)
            for i in range(n):
                for j in range(n):
                    p[i, j] = p[i, j] + q[i, j]
        x[_X, 0] = x[_X, 0] + v * h * c
        x[_Y, 0] = x[_Y, 0] + v * h * s
        x[_YAW, 0] = yaw + w * h
    _subtract_symmetric(p, np.zeros((n, n)))


# -- the whole wheel cycle in one call -------------------------------------------------------

#: the offsets of :func:`wheel_cycle`'s outputs in its workspace (a flat float64 array) and
#: their shapes: the wheel measurement's y, S, S^-1, K and z, the gyro measurement's, and
#: x and P after the last applied update (filterpy's x_post, P_post)
LAYOUT: dict[str, tuple[int, tuple[int, ...]]] = {}
_offset = 0
for _name, _shape in (("wy", (2, 1)), ("ws", (2, 2)), ("wsi", (2, 2)), ("wk", (6, 2)),
                      ("wz", (2, 1)), ("gy", (1, 1)), ("gs", (1, 1)), ("gsi", (1, 1)),
                      ("gk", (6, 1)), ("gz", (1, 1)), ("gr", (1, 1)), ("x_post", (6, 1)),
                      ("P_post", (6, 6)), ("x_prior", (6, 1)), ("P_prior", (6, 6))):
    LAYOUT[_name] = (_offset, _shape)
    _offset += math.prod(_shape)
WORKSPACE_SIZE = _offset
(_WY, _WS, _WSI, _WK, _WZ, _GY, _GS, _GSI, _GK, _GZ, _GR, _XPOST, _PPOST, _XPRIOR,
 _PPRIOR) = (LAYOUT[k][0] for k in LAYOUT)
_H_GYRO = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 1.0]])
_H_TWIST = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
_KEEP_WHEEL = np.array([0, 0, 0, 1, 1, 0], dtype=np.uint8)  # x, y, yaw, b: consider states
_KEEP_GYRO_MOVING = np.array([1, 1, 1, 1, 1, 0], dtype=np.uint8)  # b: a consider state
_KEEP_ALL = np.ones(6, dtype=np.uint8)


@_jit
def _view(ws: np.ndarray, offset: int, rows: int, cols: int) -> np.ndarray:
    return ws[offset:offset + rows * cols].reshape((rows, cols))


@_jit
def _post(x: np.ndarray, p: np.ndarray, ws: np.ndarray, xo: int, po: int) -> None:
    """Copy ``x`` and ``p`` into the workspace at offsets ``xo`` and ``po``."""
    for i in range(6):
        ws[xo + i] = x[i, 0]
        for j in range(6):
            ws[po + 6 * i + j] = p[i, j]


@_jit
def wheel_cycle(
    x: np.ndarray, p: np.ndarray, ws: np.ndarray, r: np.ndarray, has_gyro: bool,
    gyro_rate: float, gyro_var: float, bias_considered: bool, linear: float, angular: float,
    gate: float, dt: float, max_step: float, frozen: bool, lateral_slip_sq: float,
    rate_q: np.ndarray,
) -> tuple[float, float, bool]:
    """One wheel cycle, moving and with an ungated gyro (the driver's usual case): if ``dt`` >
    0, the rates' process noise over it (``rate_q``: the white-noise densities of v, w and
    the bias, :func:`~lowerbase.driver.ekf_model.rate_noise`) and the prior kept; the gyro's
    interval mean (``gyro_rate``, variance ``gyro_var``; the bias a consider state if
    ``bias_considered``) if ``has_gyro``, then the wheels' twist with covariance ``r``,
    gated at ``gate`` with the pose and bias as consider states, then, if it was applied, the
    pose driven over ``dt`` (:func:`drive`). The outputs go to ``ws`` (:data:`LAYOUT`).
    Returns the gyro's and the wheels' Mahalanobis^2 and whether the wheels were applied (if
    not, the caller goes on with the gate's other outcomes and drives the pose)."""
    wy, wsv, wsi, wk, wz = (_view(ws, _WY, 2, 1), _view(ws, _WS, 2, 2), _view(ws, _WSI, 2, 2),
                            _view(ws, _WK, 6, 2), _view(ws, _WZ, 2, 1))
    if dt > 0:
        p[_V, _V] += rate_q[0] * dt
        p[_W, _W] += rate_q[1] * dt
        p[_B, _B] += rate_q[2] * dt
        _post(x, p, ws, _XPRIOR, _PPRIOR)
    d2g = 0.0
    if has_gyro:
        gz, gr = _view(ws, _GZ, 1, 1), _view(ws, _GR, 1, 1)
        gz[0, 0] = gyro_rate
        gr[0, 0] = gyro_var
        keep = _KEEP_GYRO_MOVING if bias_considered else _KEEP_ALL
        d2g, _ = measure(x, p, _H_GYRO, gz, gr, keep, False, 0.0, _view(ws, _GY, 1, 1),
                         _view(ws, _GS, 1, 1), _view(ws, _GSI, 1, 1), _view(ws, _GK, 6, 1))
        _post(x, p, ws, _XPOST, _PPOST)
    wz[0, 0] = linear
    wz[1, 0] = angular
    d2, applied = measure(x, p, _H_TWIST, wz, r, _KEEP_WHEEL, True, gate, wy, wsv, wsi, wk)
    if applied:
        _post(x, p, ws, _XPOST, _PPOST)
        if dt > 0:
            drive(x, p, dt, max_step, frozen, lateral_slip_sq)
    return d2g, d2, applied


class CycleWorkspace:
    """:func:`wheel_cycle`'s output array and fixed views of it: ``wheel`` and ``gyro`` (each
    y, S, S^-1, K, z of that measurement) and ``post`` (x, P after the last update). The
    filter hands these views to filterpy's attributes: the next cycle overwrites them."""

    def __init__(self) -> None:
        self.data = np.zeros(WORKSPACE_SIZE)
        views: dict[str, np.ndarray] = {
            name: self.data[off:off + math.prod(shape)].reshape(shape)
            for name, (off, shape) in LAYOUT.items()}
        self.wheel: tuple[np.ndarray, ...] = tuple(
            views[k] for k in ("wy", "ws", "wsi", "wk", "wz"))
        self.gyro: tuple[np.ndarray, ...] = tuple(
            views[k] for k in ("gy", "gs", "gsi", "gk", "gz"))
        self.post: tuple[np.ndarray, np.ndarray] = (views["x_post"], views["P_post"])
        self.prior: tuple[np.ndarray, np.ndarray] = (views["x_prior"], views["P_prior"])


_compiled = False


def compile_kernels() -> None:
    """Run each kernel once on scratch arrays of the filter's types, so that they are compiled
    (or loaded from numba's cache: about 0.3 s; compiling takes seconds, once per install)
    when a filter is made, not at its first measurement in a running receive loop."""
    global _compiled
    if _compiled:
        return
    x, p, r = np.zeros((6, 1)), np.eye(6), np.eye(2)
    ws = CycleWorkspace()
    wheel_cycle(x, p, ws.data, r, True, 0.0, 1.0, True, 0.0, 0.0, 1.0, 0.02, 0.05, False, 0.0,
                np.zeros(3))
    y, s, si, k = np.empty((1, 1)), np.empty((1, 1)), np.empty((1, 1)), np.empty((6, 1))
    measure(x, p, _H_GYRO, np.zeros((1, 1)), np.eye(1), _KEEP_ALL, False, 0.0, y, s, si, k)
    drive(x, p, 0.02, 0.05, False, 0.0)
    _compiled = True
