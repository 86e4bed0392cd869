"""The compiled likelihood gather against the numpy expressions it replaced, bit for bit:
particles on, near and off the warehouse map, beams from real scans, and the score built on
it."""

from __future__ import annotations

import math

import numpy as np

from lowerbase.world.localization.likelihood import Beams, LikelihoodField
from lowerbase.world.localization.params import AmclParams
from lowerbase.world.maps import load_map
from lowerbase.world.sim import WorldConfig, WorldSim


def _same(a: np.ndarray, b: np.ndarray) -> None:
    assert a.dtype == b.dtype and a.shape == b.shape
    assert a.tobytes() == b.tobytes()


def test_gather_is_the_numpy_gather_for_particles_on_and_off_the_map() -> None:
    grid = load_map("warehouse")
    field = LikelihoodField(grid, AmclParams())
    world = WorldSim(WorldConfig(map="warehouse", start="start"))
    beams = field.beams(world.rig.scan(world.scene, world.true_pose(), 0.0), (0.0, 0.0, 0.0))
    assert beams.end_xy.shape[0] > 20
    rng = np.random.default_rng(4)
    w, h = grid.size_m
    ox, oy, _ = grid.origin
    for n in (1, 7, 500):
        poses = np.column_stack((rng.uniform(ox - 3.0, ox + w + 3.0, n),
                                 rng.uniform(oy - 3.0, oy + h + 3.0, n),
                                 rng.uniform(-math.pi, math.pi, n)))
        for got, want in zip(field.gather(poses, beams), field.gather_numpy(poses, beams),
                             strict=True):
            _same(got, want)
    odd = Beams(np.array([[1e-3, -2.5], [40.0, 0.0], [-0.3, 0.2]]), 3, 40.0)
    poses = np.array([[ox, oy, 0.0], [ox + w, oy + h, math.pi], [0.0, 0.0, -1.0]])
    for got, want in zip(field.gather(poses, odd), field.gather_numpy(poses, odd), strict=True):
        _same(got, want)
