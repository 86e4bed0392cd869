"""Localization as amcl does it: a particle filter on /odom and /scan with a likelihood field.

- ``params``: :class:`AmclParams`, amcl's parameter names and defaults;
- ``poses``: 2D pose algebra; ``motion``: amcl's "diff" odometry motion model;
- ``likelihood``: the likelihood-field laser model (scipy distance transform);
- ``particles``: weights, low-variance resampling, augmented MCL, KLD-sampling, clusters;
- ``localizer``: :class:`Localizer`, the controls (start/stop, initial pose, set_map,
  ground truth) and the outputs (:class:`PoseEstimate`).
"""

from lowerbase.world.localization.localizer import Localizer, LocalizerStats, PoseEstimate
from lowerbase.world.localization.params import AmclParams

__all__ = ["AmclParams", "Localizer", "LocalizerStats", "PoseEstimate"]
