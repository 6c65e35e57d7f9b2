"""Along a scan: a dent is a neck-down at its z, the axis and cylindricity of a tilted
cylinder, the spectrum of an undulating diameter."""

import numpy as np
import pytest
from _profiles import scan_cloud

from lts360.inspect.run import inspect_cloud
from lts360.inspect.scan import cylindricity, diameter_spectrum, fit_axis, lumps_and_necks


def test_a_dent_is_a_neck_down_at_its_z():
    cloud = scan_cloud(n_sections=17, dent_mm=0.1, dent_z_mm=1.36, dent_sigma_z_mm=1.0,
                       ovality_mm=0.0)
    ins = inspect_cloud(cloud)
    ev = ins.data["scan"]["events"]
    assert [e["kind"] for e in ev] == ["neck-down"]
    assert ev[0]["z_extreme_mm"] == pytest.approx(1.36)  # a section sits on the dent
    # Dmin falls by 0.1·exp(−Δz²/2σ²) > 0.05 mm over |Δz| < 1.18 mm: 3 sections of 0.68 mm
    assert ev[0]["length_mm"] == pytest.approx(3 * 0.68)
    assert ev[0]["z_start_mm"] == pytest.approx(0.68) and ev[0]["z_end_mm"] == pytest.approx(2.04)
    assert ev[0]["deviation_mm"] == pytest.approx(-0.1, abs=0.005)  # the bins' averaging


def test_a_lump_is_found_too():
    z = np.arange(10) * 0.5
    dmax = np.full(10, 20.0)
    dmax[6:8] += 0.08
    ev = lumps_and_necks(z, np.full(10, 19.9), dmax, threshold_mm=0.05)
    assert [(e.kind, e.z_start_mm, e.z_end_mm, e.length_mm) for e in ev] == [
        ("lump", 3.0, 3.5, pytest.approx(1.0))]


def test_an_event_must_stand_out_of_the_extremes_noise_tail():
    """20 sections, each D max with noise u = 17 µm (the realistic PVC scan's): noise alone
    moves one section's D max 54 µm above the median with p ≈ 0.01 (its Gumbel tail), far above
    the scan's false-event rate shared by 40 tests: not significant; 150 µm is (p ≈ 1e-5)."""
    z = np.arange(20) * 1.0
    u = np.full(20, 0.017)
    for bump, significant in ((0.054, False), (0.150, True)):
        dmax = np.full(20, 32.4)
        dmax[12] += bump
        ev = lumps_and_necks(z, np.full(20, 31.6), dmax, threshold_mm=0.05, u_d_min_mm=u,
                             u_d_max_mm=u)
        assert [e.kind for e in ev] == ["lump"] and ev[0].significant is significant
        beta = np.hypot(0.017, 1.2533 * 0.017 / np.sqrt(20)) * np.sqrt(6) / np.pi
        assert ev[0].p_noise == pytest.approx(1 - np.exp(-np.exp(-bump / beta - 0.3665)))


def test_a_dent_as_long_as_the_scan_is_not_taken_for_noise():
    """A 0.4 mm neck-down over the whole 10 mm scan (the rendered PVC pipe's dent, seen from
    inside it), D min's noise u = 20 µm: the deviations' spread along z is the dent, not noise,
    and the neck-down is significant (the scan's section-to-section noise is read from the
    second differences along z, which a smooth dent hardly moves)."""
    z = np.arange(10) - 4.5
    rng = np.random.default_rng(5)
    dmin = 31.6 - 0.4 * np.exp(-z**2 / (2 * 2.5**2)) + 0.02 * rng.standard_normal(10)
    u = np.full(10, 0.020)
    ev = lumps_and_necks(z, dmin, np.full(10, 32.4), threshold_mm=0.05, u_d_min_mm=u,
                         u_d_max_mm=u)
    assert [(e.kind, e.significant) for e in ev] == [("neck-down", True)]
    assert ev[0].u_mm < 0.03  # the section's own u, not the dent's spread (~0.15 mm)


def test_axis_and_cylindricity_of_a_tilted_cylinder():
    z = np.linspace(-5, 5, 11)
    th = np.radians(np.arange(0, 360, 1.0))
    slope = 0.01
    # a cylinder of radius R tilted in x cut by horizontal planes: ellipses R/cos × R
    R, c = 6.0, np.cos(np.arctan(slope))
    prof = [np.column_stack([R / c * np.cos(th) + slope * zz, R * np.sin(th)]) for zz in z]
    ax = fit_axis(z, [p.mean(axis=0) for p in prof])
    assert ax.tilt_deg == pytest.approx(np.degrees(np.arctan(slope)), abs=1e-9)
    assert ax.straightness_mm == pytest.approx(0.0, abs=1e-9)
    cyl = cylindricity(z, prof)
    assert cyl["radius_mm"] == pytest.approx(R, abs=1e-7)
    assert cyl["cylt_mm"] < 1e-6


def test_the_spectrum_finds_an_undulation_along_z():
    z = np.arange(40) * 0.34
    d = 8.0 + 0.004 * np.sin(2 * np.pi * z / (10 * 0.34)) + 0.001 * z
    s = diameter_spectrum(z, d)
    assert s["dominant_wavelength_mm"] == pytest.approx(3.4)
    assert s["dominant_amplitude_mm"] == pytest.approx(0.004, rel=0.05)  # detrend leakage
