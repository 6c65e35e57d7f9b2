"""Every material's BSDF: directional albedo at normal incidence against its closed form
``(1 − w)·ρ + w·F₀`` (GGX loses little energy to masking at normal incidence), never above 1."""

from __future__ import annotations

import numpy as np
import pytest

from lts360.scenes.materials import MATERIALS
from lts360.simulator.materials import material_to_bsdf

mi = pytest.importorskip("mitsuba", reason="the simulator needs Mitsuba 3")


@pytest.fixture(scope="module")
def variant():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")


def _albedo(bsdf, cos_theta, n=1 << 16, seed=0):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f)
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    s = float(np.sqrt(1.0 - cos_theta ** 2))
    si.wi = mi.Vector3f(s, 0.0, float(cos_theta))
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    _, w = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(), sampler.next_2d())
    return float(np.mean(np.array(w[0] if mi.is_monochromatic else mi.luminance(w))))


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_albedo_at_normal_incidence(variant, name):
    m = MATERIALS[name]
    bsdf = mi.load_dict(material_to_bsdf(m))
    a = _albedo(bsdf, 1.0)
    f0 = ((m.eta - 1) ** 2 + m.k ** 2) / ((m.eta + 1) ** 2 + m.k ** 2)
    expected = (1 - m.specular_weight) * m.diffuse_reflectance + m.specular_weight * f0
    # GGX at α ≤ 0.6 and normal incidence loses < 3 % to masking-shadowing; 2^16 samples.
    assert a == pytest.approx(expected, rel=0.04), (a, expected)
    assert _albedo(bsdf, 0.3) <= 1.0
