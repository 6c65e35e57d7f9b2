"""Design parameters: validation, and a design written as a rig TOML that load_rig reads back."""

from __future__ import annotations

import numpy as np
import pytest

from lts360.design.params import PARAMETERS, DesignError, DesignSpace
from lts360.scenes.rig_io import load_rig


def test_bad_input_names_the_parameter():
    with pytest.raises(DesignError, match="unknown design parameter 'alpha'"):
        DesignSpace.create("paper", free=["alpha"])
    with pytest.raises(DesignError, match=r"bounds of alpha_deg: \(5, 50\) outside"):
        DesignSpace.create("paper", bounds={"alpha_deg": (5.0, 50.0)})
    with pytest.raises(DesignError, match="lo < hi"):
        DesignSpace.create("paper", bounds={"f_number": (4.0, 2.0)})
    with pytest.raises(DesignError, match="not a free parameter"):
        DesignSpace.create("paper", free=["alpha_deg"], bounds={"beta_deg": (80.0, 100.0)})


def test_at_least_ten_parameters_each_a_rig_field():
    assert len(PARAMETERS) >= 10
    sp = DesignSpace.create("paper")
    assert sp.values() == pytest.approx({p.name: v for p, v in
                                         zip(PARAMETERS, sp.base_x())})


def test_design_toml_round_trip(tmp_path):
    sp = DesignSpace.create("paper")
    x = sp.from_scaled(np.linspace(0.2, 0.8, len(sp.free)))
    path = tmp_path / "rig.toml"
    path.write_text(sp.toml(x, name="opt"))
    rig = load_rig(path)
    back = DesignSpace.create(rig)
    np.testing.assert_allclose(back.base_x(), x, rtol=1e-12)
    assert rig.laser.m_squared == pytest.approx(sp.base.laser.m_squared, rel=1e-9)
    assert rig.laser.waist_distance_mm == pytest.approx(x[sp.free.index("laser_distance_mm")])
