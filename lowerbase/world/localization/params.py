"""The localizer's parameters: amcl's names (``~param`` of the amcl node) and amcl's defaults.

Where lowerbase departs from amcl's default the field says so. Values are checked once, at
construction: a bad one is a :class:`~lowerbase.errors.ConfigError` naming the parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from lowerbase.errors import ConfigError


@dataclass(frozen=True)
class AmclParams:
    """Particle filter, motion model, laser model and lost/converged thresholds.

    Filter (amcl: ``min_particles``, ``max_particles``, ``kld_err``, ``kld_z``,
    ``update_min_d``, ``update_min_a``, ``recovery_alpha_slow``, ``recovery_alpha_fast``,
    ``initial_cov_xx`` ...). ``kld_sampling=False`` keeps ``max_particles`` particles always.
    """

    # -- filter -------------------------------------------------------------------------------
    min_particles: int = 100
    max_particles: int = 5000
    kld_sampling: bool = True          #: False: a fixed count of max_particles
    kld_err: float = 0.01
    #: amcl's "upper standard normal quantile", used as the z value itself, as amcl does
    kld_z: float = 0.99
    kld_bin_xy: float = 0.5            #: KLD / cluster histogram bins [m] (amcl: 0.5)
    kld_bin_yaw: float = math.radians(10.0)
    update_min_d: float = 0.2          #: filter update after this much travel [m]
    update_min_a: float = math.pi / 6  #: ... or this much rotation [rad]
    #: resample when N_eff < resample_ess * N (amcl's selective_resampling uses 0.5;
    #: amcl's default is resampling every resample_interval=2 updates)
    resample_ess: float = 0.5
    #: augmented MCL's random particles, off as amcl's defaults (0.0). amcl's suggested values
    #: (0.001 / 0.1) re-localize a kidnapped robot while it drives, but also fire on what is
    #: not a kidnap: a robot pushing a crate 27 s with them on jumped 21 m / 163 deg to a
    #: look-alike aisle of the warehouse (issue 22 item 24). A lost estimate is reported
    #: (``lost``); /global_localization re-localizes it
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    #: lowerbase: inject only when w_diff exceeds this (amcl: any w_diff > 0), so that the
    #: fit's ordinary scan-to-scan jitter does not keep scattering particles
    recovery_min_w_diff: float = 0.1
    initial_pose_x: float = 0.0
    initial_pose_y: float = 0.0
    initial_pose_a: float = 0.0
    initial_cov_xx: float = 0.5 * 0.5
    initial_cov_yy: float = 0.5 * 0.5
    initial_cov_aa: float = (math.pi / 12) ** 2
    # -- odometry motion model ("diff") ---------------------------------------------------------
    #: lowerbase: 0.05 each, amcl's defaults are 0.2, for wheel-only odometry. The driver's
    #: /odom heading is the gyro's (0.3 % scale error), its distance the encoders' (about 1 %):
    #: with 0.2 every 30 deg turn in place scattered the particles by 23 cm (alpha4) and 13 deg
    #: (alpha1), and bench_world_loop's p95 error was 6-7 cm. Much lower (alpha4 0.01) lets a
    #: wrong initial pose converge and read found (test_a_wrong_initial_pose_reads_lost_...)
    odom_alpha1: float = 0.05  #: rotation noise from rotation
    odom_alpha2: float = 0.05  #: rotation noise from translation
    odom_alpha3: float = 0.05  #: translation noise from translation
    odom_alpha4: float = 0.05  #: translation noise from rotation
    #: lowerbase (amcl has none): before each update, cut the odometry step to the fraction
    #: of its translation the scan fits best, when that beats the whole step by more than
    #: slip_min_log_ratio (the laser model's log-likelihood): wheels spinning against a wall
    #: count distance the base never moved (slipcheck.py). Only while the particles have
    #: converged (amcl's pf: all within 0.5 m of their mean): a spread cloud has no one pose
    slip_check: bool = True
    slip_min_log_ratio: float = 1.0
    # -- likelihood-field laser model ------------------------------------------------------------
    laser_model_type: str = "likelihood_field_prob"  #: amcl default: "likelihood_field"
    laser_max_beams: int = 60            #: amcl default 30
    #: lowerbase: the likelihood is raised to this power (1: amcl); < 1 treats the beams as
    #: correlated (fewer independent ones), which keeps near-miss particles alive
    laser_likelihood_exponent: float = 0.2
    laser_z_hit: float = 0.95
    laser_z_rand: float = 0.05
    laser_sigma_hit: float = 0.2
    laser_likelihood_max_dist: float = 2.0
    laser_min_range: float = -1.0  #: -1: the scan's own range_min
    laser_max_range: float = -1.0  #: -1: the scan's own range_max
    #: amcl's beam skipping (likelihood_field_prob only; amcl default False): once the filter
    #: has converged (every particle within 0.5 m of the mean in x and y, amcl's pf), a beam is
    #: left out of the scan's weighing when no more than beam_skip_threshold of the particles
    #: see its end within beam_skip_distance of a mapped obstacle: it hit something the map
    #: does not know (a crate, a person). Unless beam_skip_error_threshold of the beams would be
    #: left out: then all are used (the filter may sit at a wrong pose). lowerbase: on. Off, a
    #: crate's beams drove w_fast down, recovery read it as a kidnap and scattered particles
    #: over the repetitive warehouse until a look-alike aisle won (test_localization_obstacles)
    do_beamskip: bool = True
    beam_skip_distance: float = 0.5
    beam_skip_threshold: float = 0.3
    beam_skip_error_threshold: float = 0.9
    # -- lowerbase's lost/converged indicator (amcl has none) -------------------------------------
    lost_sigma_xy: float = 0.3        #: lost when the position sigma (largest axis) exceeds [m]
    lost_sigma_yaw: float = math.radians(15.0)  #: ... or the heading sigma exceeds [rad]
    lost_min_fit: float = 0.8         #: ... or a smaller fraction of the used beams fits the map
    fit_tolerance: float = 0.1        #: a beam fits when its end is this close to an obstacle [m]

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not math.isfinite(v):
                raise ConfigError(f"localization parameter {f.name} must be finite, got {v!r}")
        positive = ("laser_likelihood_exponent", "kld_err", "kld_bin_xy", "kld_bin_yaw",
                    "laser_sigma_hit",
                    "laser_likelihood_max_dist", "lost_sigma_xy", "lost_sigma_yaw",
                    "fit_tolerance", "beam_skip_distance", "slip_min_log_ratio")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(f"localization parameter {name} must be > 0, "
                                  f"got {getattr(self, name)!r}")
        nonneg = ("update_min_d", "update_min_a", "odom_alpha1", "odom_alpha2", "odom_alpha3",
                  "odom_alpha4", "laser_z_hit", "laser_z_rand", "recovery_alpha_slow",
                  "recovery_alpha_fast", "initial_cov_xx", "initial_cov_yy", "initial_cov_aa")
        for name in nonneg:
            if getattr(self, name) < 0:
                raise ConfigError(f"localization parameter {name} must be >= 0, "
                                  f"got {getattr(self, name)!r}")
        if not 1 <= self.min_particles <= self.max_particles:
            raise ConfigError(f"localization needs 1 <= min_particles <= max_particles, got "
                              f"{self.min_particles} and {self.max_particles}")
        if self.laser_max_beams < 2:
            raise ConfigError(f"localization parameter laser_max_beams must be >= 2, "
                              f"got {self.laser_max_beams}")
        if self.kld_z <= 0:
            raise ConfigError(f"localization parameter kld_z must be > 0, got {self.kld_z}")
        if self.laser_model_type not in ("likelihood_field", "likelihood_field_prob"):
            raise ConfigError("localization parameter laser_model_type must be likelihood_field"
                              f" or likelihood_field_prob, got {self.laser_model_type!r}")
        for name in ("resample_ess", "lost_min_fit", "recovery_min_w_diff",
                     "beam_skip_threshold", "beam_skip_error_threshold"):
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(f"localization parameter {name} must be in [0, 1], "
                                  f"got {getattr(self, name)}")
        if self.laser_z_hit + self.laser_z_rand <= 0:
            raise ConfigError("localization needs laser_z_hit + laser_z_rand > 0")
        slow, fast = self.recovery_alpha_slow, self.recovery_alpha_fast
        if fast > 1 or (slow > 0 and fast > 0 and slow >= fast):
            raise ConfigError("localization needs 0 < recovery_alpha_slow < recovery_alpha_fast "
                              f"<= 1 (or either 0: recovery off), got {slow} and {fast}")

    @property
    def initial_cov(self) -> tuple[float, float, float]:
        return self.initial_cov_xx, self.initial_cov_yy, self.initial_cov_aa
