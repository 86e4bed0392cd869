"""The EKF's arrays, under the names of filterpy's ``ExtendedKalmanFilter`` (``x``, ``P``,
``F``, ``Q``, ``R``, ``z``, ``y``, ``K``, ``S``, ``SI``, ``x_prior``, ``P_prior``, ``x_post``,
``P_post``), initialised as filterpy initialises them.

The planar EKF (:mod:`lowerbase.driver.ekf_state`) does its own predict and its updates
compiled; of filterpy's filter it kept only these attributes. Importing ``filterpy.kalman`` costs
a fresh process 1.5-2.7 s (the package imports all its filters, and scipy.stats through
``filterpy.stats``): most of a campaign worker's start. tests/driver/test_ekf.py checks the
update against filterpy's own ``ExtendedKalmanFilter.update`` on these arrays.
"""

from __future__ import annotations

import numpy as np


class FilterState:
    """``dim_x`` states, ``dim_z`` measurements: x = 0, P = F = Q = I, R = I (dim_z), the
    residual and gain arrays zero, ``z`` unset (None), priors and posteriors copies of x, P."""

    def __init__(self, dim_x: int, dim_z: int) -> None:
        self.dim_x, self.dim_z = dim_x, dim_z
        self.x = np.zeros((dim_x, 1))
        self.P = np.eye(dim_x)
        self.F = np.eye(dim_x)
        self.Q = np.eye(dim_x)
        self.R = np.eye(dim_z)
        self.z = np.array([[None]] * dim_z)
        self.y = np.zeros((dim_z, 1))
        self.K = np.zeros((dim_x, 1))
        self.S = np.zeros((dim_z, dim_z))
        self.SI = np.zeros((dim_z, dim_z))
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
