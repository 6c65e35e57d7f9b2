"""End to end on a rendered image: render the plug gauge → inverse triangulation → score.

True calibration (frame.json), pinhole optics, no sensor noise, 16 spp.  Measured 2026-11-23
with reflected rays started on the mirror (radius bias of the circle fit / rms of the
per-point radial error, µm; coverage 360° in every case; float = the frame's radiance, 8-bit =
its image; per view, centroid/Keys/float: direct −1.6, left −3.0, right −3.0 µm):

                 Keys interpolation          B-spline interpolation
  detector       float         8-bit         float         8-bit
  centroid       −2.68  4.55   −2.55  4.73   −2.58  3.97   −2.46  3.99
  gauss          −2.40  4.69   −2.32  4.84   −2.30  3.91   −2.23  3.94
  steger (0.6)   −3.12  4.31   −3.11  4.31   −3.03  3.92   −3.02  3.93

(Before the simulator fix below the same table read −0.70 / 3.91 µm for centroid/Keys/float.)

Where the error comes from (centroid, 10 % threshold, float radiance; each part measured by
re-rendering the same frame with one cause changed — sheet waist, 3× pixel density at the same
field of view, 1024 spp, reflected rays started on the mirror — and scoring it the same way):

* **Sampling of a ~1 px line (pixel locking)** — the largest part of the scatter: 3.2 µm rms,
  zero mean, against the same detector on a render at 3× the pixel density.  The laser line is
  0.7 px (mirror views) to 1 px (direct) σ: the image is undersampled and its aliased spectrum
  moves the centre with the sub-pixel phase of the line.  Cubic B-spline interpolation cuts it to
  2.4 µm; a near-ideal (Lanczos-6) interpolator still leaves 2.0 µm — the aliasing no
  interpolation removes.  Averaging over 1 px of arc along θ removes only ~15 % (the error varies
  slowly along the line).  A lower threshold lowers it (2 %: 1.7 µm) but adds sheet bias (below).
* **Laser-sheet thickness (physics)** — with sampling errors removed (3× pixel density) the
  line centre lies −1.5 µm (direct view) and +0.2 µm (mirror views) from the surface, 2.0 µm
  rms about the circle.  It scales with the waist² (w₀ = 150 / 300 / 600 µm: −0.5 / −1.5 /
  −5.7 µm in the direct view): the stripe is the image of a band of height σ_z = 150 µm on a
  curved surface seen obliquely, so its profile along the grid ray is skewed (a ray-cast model
  of a Gaussian sheet on the cylinder gives −1.1 µm direct, −2.8 µm mirrors), and the glossy
  steel's brightness changes across the band (not separable from a shift).  It depends on the
  detector and threshold (3×, circle bias: threshold 20 / 10 / 5 / 0 % → +0.5 / −0.2 / −0.8 /
  −2.1 µm); a peak-seeking fit sees less of it (3-point Gauss) but has 2–4× the sampling error.
* **Simulator: mirror views were shifted by +2.6 µm (fixed)** — Mitsuba's ``spawn_ray`` after
  a mirror bounce started the reflected ray ~7 µm off the mirror along its normal (ray epsilon
  × |p|); traced rays through the projected circle hit the gauge 2.3 µm above the laser plane
  in the mirror views.  It happened to cancel the sheet bias of the mirror views.  The
  integrator now starts the reflected ray on the exact reflected line; the table above is
  measured with that fix (mirror views −3.0 µm, as the ray-cast model of the sheet predicts).
* **Render noise** (16 vs 1024 spp): 0.8 µm rms.  **8-bit image**: the 25.5 DN threshold is
  12 % of the 208 DN line (float: 10 % of the maximum), +1.5 µm rms; rounding +1.0 µm rms.

Issue 4's targets (|bias| ≤ 1 µm, rms ≤ 2 µm) are out of reach on this rig on physical
grounds: the sheet alone leaves 2.7 µm rms at unlimited resolution and a −1.5 to −3 µm bias
(the views differ), and the undersampled line adds ≥ 2 µm with any interpolation.  The
tolerances below guard the measured figures: bias within 0.5 µm of the table (the mirror-bounce
offset moved it by ~2 µm), rms within 10 %.
"""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3")

from lts360.experiments.score import score_cloud  # noqa: E402
from lts360.recon.model import calibration_from_frame_truth  # noqa: E402
from lts360.recon.triangulation.grid import CylGrid  # noqa: E402
from lts360.recon.triangulation.inverse import inverse_triangulate  # noqa: E402
from lts360.recon.triangulation.measure import result_to_cloud  # noqa: E402
from lts360.scenes.objects import build_object  # noqa: E402
from lts360.scenes.rig_io import load_rig  # noqa: E402

#: Measured (bias µm, rms µm) per (detector, interpolation, image) — see the module docstring.
MEASURED = {
    ("centroid", "keys", "float"): (-2.68, 4.55), ("centroid", "keys", "8bit"): (-2.55, 4.73),
    ("gauss", "keys", "float"): (-2.40, 4.69), ("gauss", "keys", "8bit"): (-2.32, 4.84),
    ("steger", "keys", "float"): (-3.12, 4.31), ("steger", "keys", "8bit"): (-3.11, 4.31),
    ("centroid", "bspline", "float"): (-2.58, 3.97), ("centroid", "bspline", "8bit"): (-2.46, 3.99),
    ("gauss", "bspline", "float"): (-2.30, 3.91), ("gauss", "bspline", "8bit"): (-2.23, 3.94),
    ("steger", "bspline", "float"): (-3.03, 3.92), ("steger", "bspline", "8bit"): (-3.02, 3.93),
}
#: Bias tolerance: the renderer is seeded; 0.5 µm covers float-rounding differences between
#: builds but not a change of the simulated physics (the mirror-bounce offset is ~2 µm).
BIAS_SLACK_UM = 0.5
#: RMS tolerance: 10 % above the measured value.
RMS_FACTOR = 1.10


@pytest.fixture(scope="module")
def rendered():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    import json

    from lts360.simulator.frame import simulate_frame

    obj = build_object("plug-gauge")
    # Full frames: the aperture test compares this frame point by point with thin-lens frames
    # of the same seed, whose noise cancels only when every pixel gets the same samples (a
    # pixel support depends on the optics, and its pixels' samples on the support).
    frame = simulate_frame(load_rig("paper"), obj, spp=16, seed=11, thin_lens=False,
                           support="full")
    truth = json.loads(json.dumps(frame.truth, default=lambda v: v.tolist()))
    return obj, frame, calibration_from_frame_truth(truth)


@pytest.mark.parametrize("peak,interpolation,kind", sorted(MEASURED))
def test_plug_gauge_from_its_image(rendered, peak, interpolation, kind):
    obj, frame, cal = rendered
    image = frame.image if kind == "8bit" else frame.render.radiance_W_m2_sr.astype(np.float64)
    grid = CylGrid.from_ranges((8.0, 12.0), theta_step_deg=0.2, r_step_mm=0.005)
    opts = {"line_width_mm": 0.6} if peak == "steger" else None
    res = inverse_triangulate(image, cal, grid, peak=peak, peak_options=opts,
                              interpolation=interpolation)
    m = score_cloud(result_to_cloud(res, z_mm=0.0, section=0), obj, use_mesh=False)
    bias_um, rms_um = MEASURED[(peak, interpolation, kind)]
    assert m["coverage_deg"] >= 0.99 * 360.0
    assert abs(m["radius_bias_mm"] * 1e3 - bias_um) <= BIAS_SLACK_UM, m["radius_bias_mm"]
    assert m["rms_mm"] * 1e3 <= RMS_FACTOR * rms_um, m["rms_mm"]
    for view in ("direct", "left", "right"):
        assert m["views"][view]["n"] > 300


def test_classic_baseline_on_the_same_image(rendered):
    """Forward triangulation (Steger 2-D centres, rays ∩ laser plane) on the same image.

    Measured: radius bias −3.6 µm, RMS 4.7 µm (−1.4 / 4.0 before the mirror-bounce fix),
    ~490 points (one per stripe pixel) against the inverse method's 4385 (one per 0.1° per
    view).
    """
    from lts360.recon.triangulation.classic import classic_triangulate
    from lts360.recon.triangulation.measure import classic_to_cloud

    obj, frame, cal = rendered
    grid = CylGrid.from_ranges((8.0, 12.0), theta_step_deg=0.2, r_step_mm=0.005)
    res = classic_triangulate(frame.image, cal, grid)
    m = score_cloud(classic_to_cloud(res, z_mm=0.0, section=0), obj, use_mesh=False)
    for view in ("direct", "left", "right"):
        assert m["views"][view]["n"] > 80
        # Points lie on the laser plane exactly (ray ∩ plane).
        assert np.abs(res[view]["points_meas_mm"][:, 2]).max() < 1e-9
    assert abs(m["radius_bias_mm"]) * 1e3 <= 4.5
    assert m["rms_mm"] * 1e3 <= 8.0


@pytest.mark.slow
def test_the_lens_aperture_shifts_only_the_defocused_views(rendered):
    """The same frame through the thin lens, radii point by point against the pinhole frame
    (16 spp, seed 11, 8-bit, true calibration).  Measured 2026-12-02:

                                   direct   left    right   (mean shift of the radii, µm)
      f/2.8 focused at 195 mm      −3.35   −1.08   −0.26    (the paper preset)
      f/8   focused at 195 mm      −0.50   −0.24   −0.03
      f/2.8 focused on the gauge's
            front (157 mm)         −0.07   −0.57   −12.3    (direct: +0.05 at its front ±20°)

    In focus the thin lens images like the pinhole (every pupil ray meets the surface point of
    its pixel): a check of the thin-lens integration.  Out of focus the blurred stripe's
    centre along the grid ray moves inwards; the shift grows with the aperture (f/2.8 against
    f/8: 6.7×, the pupil area 8.2×).  The direct view, 38 mm before the focus plane at its
    front, loses 3.4 µm at f/2.8; the mirror views, 30–50 mm behind it, far less.  The part
    of the gauge's −4.3 µm (true calibration, thin lens, 64 spp) that the pinhole's −2.6 µm
    does not explain.
    """
    import dataclasses

    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    obj, frame, cal = rendered
    grid = CylGrid.from_ranges((8.0, 12.0), theta_step_deg=0.2, r_step_mm=0.005)

    def radii(image, c):
        res = inverse_triangulate(image, c, grid)
        return {n: np.where(v.valid, v.r_mm, np.nan) for n, v in res.views.items()}

    pin = radii(frame.image, cal)
    rig = load_rig("paper")
    front_depth = float((cal.T_cam_meas @ np.array([0.0, -10.0, 0.0, 1.0]))[2])  # faces the camera
    cams = {"f/2.8": rig.camera, "f/8": dataclasses.replace(rig.camera, f_number=8.0),
            "front": dataclasses.replace(rig.camera, focus_distance_mm=front_depth)}
    shift = {}
    for name, cam in cams.items():
        f = simulate_frame(dataclasses.replace(rig, camera=cam), obj, spp=16, seed=11,
                           thin_lens=True, support="full")
        r = radii(f.image, cal)
        shift[name] = {v: 1e3 * float(np.nanmean(r[v] - pin[v])) for v in pin}
    assert abs(shift["front"]["direct"]) < 0.3, shift
    assert shift["f/2.8"]["direct"] == pytest.approx(-3.35, abs=0.5), shift
    assert shift["f/2.8"]["left"] == pytest.approx(-1.08, abs=0.5), shift
    assert shift["f/2.8"]["right"] == pytest.approx(-0.26, abs=0.5), shift
    assert -1.0 < shift["f/8"]["direct"] < 0.0 and shift["f/2.8"]["direct"] < 4 * shift["f/8"]["direct"]
