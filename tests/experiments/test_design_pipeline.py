"""``design check --pipeline``: the measured U from the sections' radius errors, a finished
seed reused without rendering, bad arguments refused before anything runs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lts360.experiments import design_pipeline as P


def test_measured_u_is_twice_the_rms_with_its_chi2_interval():
    err_mm = np.array([1.0, -2.0, 3.0, np.nan, 2.0]) * 1e-3
    m = P._measured(err_mm)
    assert m["n"] == 4 and m["failed"] == 1
    rms = math.sqrt((1 + 4 + 9 + 4) / 4)
    assert m["U_um"] == pytest.approx(2 * rms, rel=1e-12)
    assert m["mean_um"] == pytest.approx(1.0, rel=1e-12)
    lo, hi = m["U_95_um"]
    assert lo < m["U_um"] < hi
    # χ² with n = 4 degrees of freedom: 0.484 and 11.14 at 2.5 % and 97.5 %
    assert hi / m["U_um"] == pytest.approx(math.sqrt(4 / 0.4844), rel=1e-3)
    assert "U_um" not in P._measured(np.array([1e-3, np.nan]))


def test_a_finished_seed_is_read_not_rendered(tmp_path, monkeypatch):
    """A seed folder with its table and trials for the asked placements is reused; asked for
    other placements, the study runs again (here: refused by a stand-in that fails)."""
    import xarray as xr

    import lts360.experiments.gauge_study as G

    out = tmp_path / "paper" / "seed0"
    (out / "trials").mkdir(parents=True)
    (out / "table.json").write_text(json.dumps({}))
    errs = np.array([1.5, -0.5, 2.0]) * 1e-3
    xr.Dataset({"radius_error_mm": ("trial", errs)}).to_netcdf(out / "trials" / "results.nc")

    def refuse(*a, **k):
        raise AssertionError("rendered")

    monkeypatch.setattr(G, "run_plug_gauge_study", refuse)
    got, _ = P._seed_errors(out, rig="paper", seed=0, placements=3, placement_mm=0.3,
                            say=print)
    np.testing.assert_allclose(got, errs)
    with pytest.raises(AssertionError, match="rendered"):
        P._seed_errors(out, rig="paper", seed=0, placements=4, placement_mm=0.3, say=print)


@pytest.mark.parametrize("kw, message", [
    (dict(seeds=(0, 0)), "seeds: must be distinct"),
    (dict(seeds=()), "seeds: must be distinct"),
    (dict(placements=1), "placements: must be an integer >= 2"),
    (dict(placements=True), "placements: must be an integer >= 2"),
])
def test_bad_arguments(tmp_path, kw, message):
    with pytest.raises(ValueError, match=message):
        P.check_pipeline(["paper"], tmp_path, **kw)
    with pytest.raises(ValueError, match="share the folder name"):
        P.check_pipeline(["paper", "paper"], tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_rig_label():
    assert P.rig_label("paper") == "paper"
    assert P.rig_label("some/dir/opt.toml") == "opt"
