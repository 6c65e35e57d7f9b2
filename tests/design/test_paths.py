"""The design model's smooth path test (lts360.design.paths) against the one numpy test
(lts360.geometry.mirror_path, through lts360.scenes.coverage.path_valid) on random rigs."""

import math

import numpy as np
import pytest

from lts360.design.backend import DrJitOps
from lts360.design.camera import rig_geometry
from lts360.design.params import PARAMETERS, DesignSpace
from lts360.design.paths import trace
from lts360.scenes.coverage import mirror_sequences, path_valid


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smooth_trace_tends_to_the_numpy_path_test(seed):
    """At a sharp smooth step (widths 1e-4 mm), thresholded at 1/2, the model's soft validity
    of every path (camera and laser, direct and through one or two mirrors) equals the numpy
    test's on the points whose surface faces the path, except within 0.05 mm of an edge, where
    the two may legitimately differ."""
    space = DesignSpace.create("paper")
    rng = np.random.default_rng(seed)
    x = space.from_scaled(rng.uniform(0.2, 0.8, len(space.free)))
    # narrow mirrors far from the corner: their edges cut the views, so extents matter
    x[space.free.index("mirror_width_mm")] = 60.0
    x[space.free.index("mirror_corner_distance_mm")] = 90.0
    rig = space.rig(x)
    o = DrJitOps()
    values = space.values(x)
    P = {p.name: o.F(float(values[p.name])) for p in PARAMETERS}
    geo = rig_geometry(o, P, space)
    r = float(rng.uniform(4.0, 14.0))
    th = np.linspace(-math.pi, math.pi, 721)[:-1]
    X_np = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros_like(th)])
    X = o.V3(o.F(X_np[:, 0]), o.F(X_np[:, 1]), o.F(X_np[:, 2]))
    w_fine = 1e-4
    checked = 0
    for target_np, target in ((rig.camera.center_mm, geo["pos"]),
                              (rig.laser.origin_mm, geo["laser"])):
        for seq in mirror_sequences(rig.mirrors, 2):
            hard, leave, _ = path_valid(X_np, target_np, seq, rig.mirrors, r)
            # the model leaves the first leg's occlusion to its incidence test: compare the
            # points whose surface faces that leg (cos i > cos 80°, as the model's limit)
            facing = np.einsum("ij,ij->i", leave, X_np / r) > math.cos(math.radians(80.0))
            soft, _, _, _ = trace(o, X, target, seq, geo["mirrors"], (0.0, 0.0), r,
                                  w_fine, w_fine * 0.02)
            soft = np.asarray(soft.numpy() if hasattr(soft, "numpy") else [soft] * len(th))
            coarse, _, _, _ = trace(o, X, target, seq, geo["mirrors"], (0.0, 0.0), r, 0.05, 0.001)
            coarse = np.asarray(coarse.numpy() if hasattr(coarse, "numpy") else [coarse] * len(th))
            # points far from every edge: the coarse step is already saturated there
            clear = ((coarse < 1e-9) | (coarse > 1 - 1e-9)) & facing
            assert np.array_equal((soft > 0.5)[clear], hard[clear]), (seed, seq)
            checked += int(clear.sum())
    assert checked > 0.3 * 720 * 2 * len(mirror_sequences(rig.mirrors, 2))
