"""The design model against full simulation: predicted and simulated radius σ and per-point σ.

For each rig: the model (:mod:`lts360.design`) predicts, for the plug gauge's section
(Ø19.9987 mm, centred), the radius σ after the circle fit and the rms per-point σ_r; the
simulation renders the gauge once (thin lens, ``spp``) and measures ``draws`` images, each
with new EMVA 1288 sensor noise and a new speckle pattern, with the *true* calibration
(:func:`lts360.experiments.design_space.trial._monte_carlo`, as the design-space study) — the
model has no calibration term either.  The simulated σ of the radius is the standard deviation
over the draws, with its 95 % interval (χ² with draws − 1 degrees of freedom); the simulated
per-point σ is the rms of the points' radial errors (which also holds the render's fixed
errors: defocus bias, pixel locking, sampling).

With ``--shares`` (:func:`check_shares`) the radius σ of a gauge moved off the axis is split
into the model's three shares and each is simulated on its own: the measured image's noise
(true calibration, no compensation), the §4.4 compensation's noise (offsets fitted on a new
noisy reference image of the centred gauge, applied to another image) and, with a calibration
file, the calibration's (a calibration drawn from the file's covariance about the true one,
compensated on the noise-free reference, measuring the noise-free moved gauge).

Run: ``lts360 design check RIG [RIG ...] --draws 200``, or ``lts360 design check RIG --shares
--draws 60 [--placement-mm 2] [--calibration FILE] [--json OUT]``, or ``lts360 design check
RIG --calibrations FILE FILE FILE...``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from lts360.design.model import Conditions, evaluate
from lts360.design.params import DesignSpace

__all__ = ["check_rig", "check_shares", "check_calibrations", "sigma_with_interval",
           "format_shares", "share_args_error", "file_uncertainty", "MAX_PLACEMENT_MM"]

GAUGE_DIAMETER_MM = 19.9987
#: Largest placement of the shares check (mm): beyond it the gauge leaves the views' band.
MAX_PLACEMENT_MM = 10.0
#: Fewest draws of the shares check: a σ with ddof = 1 and a χ² interval needs ≥ 2 degrees
#: of freedom to mean anything.
MIN_SHARE_DRAWS = 3


def check_rig(rig, *, draws: int = 200, spp: int = 16, seed: int = 0) -> dict:
    """Model and simulation side by side for one rig (µm)."""
    from scipy.stats import chi2

    from lts360.experiments.design_space.trial import _monte_carlo
    from lts360.simulator.render import ensure_variant

    ensure_variant()
    space = DesignSpace.create(rig)
    out = {"rig": rig.name}
    for speckle in ("pixel", "dorsch"):
        # no compensation: the simulation below measures with the true calibration and
        # scores the spread of the radius error, so the model's σ_R is the image's own share
        # (Conditions compensates by default; the bias the twin would leave is a constant
        # for a given rig and gauge, not part of a spread)
        e = evaluate(space, None, Conditions(diameters_mm=(GAUGE_DIAMETER_MM,), n_theta=360,
                                             speckle=speckle, compensate=False), gradient=False)
        out[f"model_{speckle}"] = {"sigma_R_um": float(e.sigma_R_noise_um[0]),
                                   "point_rms_um": float(e.point_rms_um[0]),
                                   "speckle_rms_um": float(e.speckle_rms_um[0]),
                                   "coverage_deg": float(e.coverage_deg[0])}
    t0 = time.perf_counter()
    sim = _monte_carlo(rig, draws=draws, spp=spp, scale=1.0, seed=seed)
    err = np.asarray(sim["radius_error_mm"], dtype=float)
    err = err[np.isfinite(err)]
    n = len(err)
    s = float(np.std(err, ddof=1)) * 1e3
    lo = s * math.sqrt((n - 1) / chi2.ppf(0.975, n - 1))
    hi = s * math.sqrt((n - 1) / chi2.ppf(0.025, n - 1))
    out["simulation"] = {"sigma_R_um": s, "sigma_R_95_um": [lo, hi], "draws": n,
                         "point_rms_um": sim["point_rms_mm"] * 1e3,
                         "mean_error_um": sim["radius_mean_error_mm"] * 1e3,
                         "coverage_deg": sim["measured_coverage_deg"],
                         "seconds": time.perf_counter() - t0}
    return out

# --- the shares of the radius σ: image noise, compensation, calibration -------------------------

def sigma_with_interval(errors_mm) -> dict:
    """σ (ddof = 1) of the finite radius errors, its 95 % χ² interval and their mean (µm).

    Parameters
    ----------
    errors_mm : (n,) float
        Radius errors of the draws (mm); NaN for a draw that measured nothing.
    """
    from scipy.stats import chi2

    err = np.asarray(errors_mm, dtype=float)
    ok = err[np.isfinite(err)]
    n = len(ok)
    out = {"sigma_um": None, "sigma_95_um": None, "mean_um": None, "draws": n,
           "failed": int(len(err) - n)}
    if n >= 2:
        s = float(np.std(ok, ddof=1)) * 1e3
        out["sigma_um"] = s
        out["sigma_95_um"] = [s * math.sqrt((n - 1) / chi2.ppf(0.975, n - 1)),
                              s * math.sqrt((n - 1) / chi2.ppf(0.025, n - 1))]
    if n >= 1:
        out["mean_um"] = float(np.mean(ok)) * 1e3
    return out


def _difference_share(with_share: dict, without: dict) -> dict:
    """√(σ_with² − σ_without²) of two independent σ, with an approximate 95 % interval
    (Welch–Satterthwaite degrees of freedom of the difference of the variances); not
    resolved when σ_with ≤ σ_without."""
    from scipy.stats import chi2

    sb, sa = with_share["sigma_um"], without["sigma_um"]
    if sb is None or sa is None or not sb > sa:
        return {"sigma_um": None, "sigma_95_um": None, "resolved": False}
    d = sb ** 2 - sa ** 2
    nu = d ** 2 / (sb ** 4 / (with_share["draws"] - 1) + sa ** 4 / (without["draws"] - 1))
    return {"sigma_um": math.sqrt(d), "resolved": True, "dof": nu,
            "sigma_95_um": [math.sqrt(d * nu / chi2.ppf(0.975, nu)),
                            math.sqrt(d * nu / chi2.ppf(0.025, nu))]}


def share_args_error(draws, spp, placement_mm, calibration) -> str | None:
    """One line naming the bad argument of :func:`check_shares`, or None."""
    if isinstance(draws, bool) or not isinstance(draws, (int, np.integer)) \
            or draws < MIN_SHARE_DRAWS:
        return f"draws: must be an integer >= {MIN_SHARE_DRAWS}, got {draws!r}"
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        return f"spp: must be an integer >= 1, got {spp!r}"
    if not (isinstance(placement_mm, (int, float, np.number)) and math.isfinite(placement_mm)
            and 0.0 <= placement_mm <= MAX_PLACEMENT_MM):
        return f"placement_mm: must be in [0, {MAX_PLACEMENT_MM:g}] mm, got {placement_mm!r}"
    if calibration is not None and not Path(calibration).is_file():
        return f"calibration: no such file: {calibration}"
    return None


def file_uncertainty(path):
    """The calibration file's ``uncertainty`` dict and the file's calibration (its normals).

    Raises
    ------
    ValueError
        The file is not a calibration, or it has no uncertainty block.
    """
    from lts360.recon.model import load_calibration

    try:
        cal = load_calibration(path)
    except (OSError, KeyError, TypeError, json.JSONDecodeError) as exc:
        raise ValueError(f"calibration: cannot read {path}: {exc}") from None
    if not cal.uncertainty:
        raise ValueError(f"calibration: {path} has no uncertainty block")
    return cal.uncertainty, cal


def _oriented_uncertainty(unc: dict, file_cal, true_cal) -> dict:
    """``unc`` for planes oriented as ``true_cal``'s: a plane whose file normal points the
    other way has its ``(a, b, δ)`` covariance mapped onto the true normal's tangent basis
    (:func:`lts360.recon.calibration.uncertainty.perturb_plane`'s parameterisation)."""
    import copy

    from lts360.recon.calibration.uncertainty import tangent_basis

    out = copy.deepcopy(unc)
    true_mirrors = {m.name: m.n for m in true_cal.mirrors}
    planes = [((out.get("mirrors") or {}).get(m.name), m.n, true_mirrors.get(m.name))
              for m in file_cal.mirrors]
    planes.append((out.get("laser_plane"), file_cal.laser_plane[0], true_cal.laser_plane[0]))
    for block, n_file, n_true in planes:
        if not block or block.get("cov_abd") is None or n_true is None \
                or float(np.dot(n_file, n_true)) >= 0.0:
            continue
        e1, e2 = tangent_basis(n_file)
        f1, f2 = tangent_basis(n_true)
        # n_true + a' f1 + b' f2 = −(n_file + a e1 + b e2), d_true + δ' = −(d_file + δ)
        M = np.array([[-e1 @ f1, -e2 @ f1, 0.0], [-e1 @ f2, -e2 @ f2, 0.0], [0.0, 0.0, -1.0]])
        C = np.asarray(block["cov_abd"], dtype=float)
        block["cov_abd"] = (M @ C @ M.T).tolist()
    return out


def _planned(cal, grid):
    """The per-image measurement with ``cal``, planned: Dr.Jit's kernel, or the numpy plan."""
    from lts360.recon.triangulation.inverse import plan_inverse

    try:
        from lts360.recon.triangulation.fast import FastInverse

        return FastInverse(plan_inverse(cal, grid, precompute=False))
    except RuntimeError:  # no Dr.Jit LLVM backend: the precomputed numpy path
        return plan_inverse(cal, grid, precompute=True)


def _with_offsets(planned, offsets: dict):
    """``planned`` for its calibration with these §4.4 view offsets (they translate the
    points after the peaks: the plan's geometry stays)."""
    from lts360.recon.triangulation.fast import FastInverse

    plan = planned.plan if isinstance(planned, FastInverse) else planned
    plan = dataclasses.replace(plan, cal=dataclasses.replace(plan.cal, view_offsets_mm=offsets))
    return FastInverse(plan) if isinstance(planned, FastInverse) else plan


def _measure(planned, image, *, compensate: bool):
    from lts360.recon.triangulation.fast import FastInverse
    from lts360.recon.triangulation.inverse import inverse_triangulate

    if isinstance(planned, FastInverse):
        return planned(image, compensate=compensate)
    return inverse_triangulate(image, planned.cal, planned.grid, plan=planned,
                               compensate=compensate)


def _offsets(result) -> dict | None:
    """§4.4 view offsets of one reference measurement; None when a view saw too little."""
    from lts360.recon.calibration.compensation import joint_view_offsets

    try:
        return joint_view_offsets(result)
    except ValueError:
        return None


def _simulate_shares(rig, *, draws: int, spp: int, seed: int, placement_mm: float,
                     uncertainty: dict | None, file_cal, scale: float, progress: bool) -> dict:
    """Per-draw radius errors (mm) of the three simulated shares (see :func:`check_shares`)."""
    from lts360.experiments.design_space.settings import (
        BAND_MM,
        GAUGE_SPEC,
        R_STEP_MM,
        THETA_STEP_DEG,
    )
    from lts360.experiments.design_space.trial import _measure_draw
    from lts360.recon.calibration.uncertainty import sample_calibration
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.scenes.objects import build_object
    from lts360.simulator.frame import sensor_image, simulate_frame

    children = np.random.SeedSequence(int(seed)).spawn(draws + 1)
    render_seeds = [int(v) for v in children[0].generate_state(2)]
    t0 = time.perf_counter()
    ref_obj = build_object(GAUGE_SPEC)
    test_obj = build_object(f"{GAUGE_SPEC}:d={GAUGE_DIAMETER_MM},x={float(placement_mm)!r},y=0")
    frames = [simulate_frame(rig, o, spp=spp, seed=s, noise="none", thin_lens=True, scale=scale)
              for o, s in zip((ref_obj, test_obj), render_seeds)]
    seconds_render = time.perf_counter() - t0
    r_true = test_obj.params["diameter_mm"] / 2.0
    centre = np.asarray(test_obj.T_world_object, dtype=float)[:2, 3]
    # The truth as a file would hold it (plain JSON), as _monte_carlo does.
    truth = json.loads(json.dumps(frames[1].truth, default=lambda v: np.asarray(v).tolist()))
    cal = dataclasses.replace(calibration_from_frame_truth(truth), view_offsets_mm={})
    # One band for both placements: the moved gauge's radius about the axis spans r ± ρ.
    half = BAND_MM + float(placement_mm)
    grid = CylGrid.from_ranges((r_true - half, r_true + half), theta_step_deg=THETA_STEP_DEG,
                               r_step_mm=R_STEP_MM)
    true_plan = _planned(cal, grid)

    def image(k, noise_seed=None):
        noisy = noise_seed is not None
        return sensor_image(rig, frames[k].render, noise="realistic" if noisy else "none",
                            seed=int(noise_seed) if noisy else 0, scale=scale)[0]

    def error(result):
        return _measure_draw(result, r_true, centre)["radius_error_mm"]

    ref_clean, test_clean = image(0), image(1)
    drawn_unc = None if uncertainty is None else _oriented_uncertainty(uncertainty, file_cal, cal)
    cal_u = None if drawn_unc is None else dataclasses.replace(cal, uncertainty=drawn_unc)
    nan = math.nan
    rows = {k: [] for k in ("noise", "compensation", "compensation_paired_uncompensated",
                            "calibration")}
    items = range(draws)
    if progress:
        try:
            from tqdm import tqdm

            items = tqdm(items, desc=f"{rig.name} shares", unit="draw", file=sys.stderr)
        except ImportError:  # progress bars are a nicety
            pass
    t1 = time.perf_counter()
    for i in items:
        s_a, s_ref, s_test, s_cal = (int(v) for v in children[i + 1].generate_state(4))
        # a. the image's own noise: true calibration, no compensation
        rows["noise"].append(error(_measure(true_plan, image(1, s_a), compensate=False)))
        # b. + the compensation's noise: offsets from a new noisy reference image, applied to
        #    a new noisy image of the moved gauge (also measured uncompensated: paired check)
        offsets = _offsets(_measure(true_plan, image(0, s_ref), compensate=False))
        test = image(1, s_test)
        rows["compensation_paired_uncompensated"].append(
            error(_measure(true_plan, test, compensate=False)))
        rows["compensation"].append(
            nan if offsets is None
            else error(_measure(_with_offsets(true_plan, offsets), test, compensate=True)))
        # c. the calibration: drawn about the truth, compensated on the noise-free reference,
        #    measuring the noise-free moved gauge
        if cal_u is not None:
            drawn = dataclasses.replace(sample_calibration(cal_u, np.random.default_rng(s_cal)),
                                        view_offsets_mm={})
            plan_c = _planned(drawn, grid)
            offsets_c = _offsets(_measure(plan_c, ref_clean, compensate=False))
            rows["calibration"].append(
                nan if offsets_c is None
                else error(_measure(_with_offsets(plan_c, offsets_c), test_clean,
                                    compensate=True)))
    clean = {"uncompensated_error_um": 1e3 * error(_measure(true_plan, test_clean,
                                                            compensate=False))}
    offsets0 = _offsets(_measure(true_plan, ref_clean, compensate=False))
    if offsets0 is not None:
        clean["compensated_error_um"] = 1e3 * error(
            _measure(_with_offsets(true_plan, offsets0), test_clean, compensate=True))
        clean["view_offsets_um"] = {k: (1e3 * np.asarray(v)).tolist()
                                    for k, v in offsets0.items()}
    return {"errors_mm": {k: np.asarray(v, dtype=float) for k, v in rows.items()},
            "noise_free": clean, "seconds_render": seconds_render,
            "seconds_draws": time.perf_counter() - t1,
            "band_mm": [r_true - half, r_true + half], "true_calibration": cal}


def check_calibrations(rig, files, *, spp: int = 16, seed: int = 0,
                       placement_mm: float = 2.0) -> dict:
    """The calibration's share from real calibrations: each file (``lts360 calibrate`` of this
    rig, e.g. with other seeds: other boards, renders and noise) compensated on the noise-free
    centred gauge and measuring the noise-free gauge moved by ``placement_mm`` — the whole
    pipeline, render → calibrate → compensate → measure, once per calibration.

    Returns the radius error of each calibration (µm, compensated and not), their σ with its
    95 % interval, and the model's share for the plan's predicted covariance and for each
    file's own covariance.
    """
    from lts360.design.calib_covariance import plan_covariance
    from lts360.design.model import Conditions, evaluate
    from lts360.design.params import DesignSpace
    from lts360.design.shares import CalibrationCovariance
    from lts360.experiments.design_space.settings import (
        BAND_MM,
        GAUGE_SPEC,
        R_STEP_MM,
        THETA_STEP_DEG,
    )
    from lts360.experiments.design_space.trial import _measure_draw
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.scenes.objects import build_object
    from lts360.simulator.frame import sensor_image, simulate_frame
    from lts360.simulator.render import ensure_variant

    if len(files) < 3:
        raise ValueError(f"check_calibrations: need at least 3 calibration files, got {len(files)}")
    ensure_variant()
    render_seeds = [int(v) for v in np.random.SeedSequence(int(seed)).generate_state(2)]
    ref_obj = build_object(GAUGE_SPEC)
    test_obj = build_object(f"{GAUGE_SPEC}:d={GAUGE_DIAMETER_MM},x={float(placement_mm)!r},y=0")
    frames = [simulate_frame(rig, o, spp=spp, seed=s, noise="none", thin_lens=True)
              for o, s in zip((ref_obj, test_obj), render_seeds)]
    ref_img, test_img = (sensor_image(rig, f.render, noise="none", seed=0)[0] for f in frames)
    r_true = test_obj.params["diameter_mm"] / 2.0
    centre = np.asarray(test_obj.T_world_object, dtype=float)[:2, 3]
    half = BAND_MM + float(placement_mm)
    grid = CylGrid.from_ranges((r_true - half, r_true + half), theta_step_deg=THETA_STEP_DEG,
                               r_step_mm=R_STEP_MM)
    rows = []
    for path in files:
        cal = dataclasses.replace(load_calibration(str(path)), view_offsets_mm={})
        planned = _planned(cal, grid)
        raw = _measure_draw(_measure(planned, test_img, compensate=False), r_true, centre)
        offsets = _offsets(_measure(planned, ref_img, compensate=False))
        comp = (math.nan if offsets is None else _measure_draw(
            _measure(_with_offsets(planned, offsets), test_img, compensate=True), r_true,
            centre)["radius_error_mm"])
        cov = CalibrationCovariance.from_file(path)
        e = evaluate(DesignSpace.create(rig), None,
                     Conditions(diameters_mm=(GAUGE_DIAMETER_MM,), placement_mm=placement_mm,
                                n_theta=360, calibration=cov), gradient=False)
        rows.append({"file": str(path), "error_um": 1e3 * comp,
                     "error_uncompensated_um": 1e3 * raw["radius_error_mm"],
                     "model_file_covariance_um": float(e.sigma_R_cal_um[1])})
    err = np.array([r["error_um"] for r in rows]) * 1e-3
    plan = evaluate(DesignSpace.create(rig), None,
                    Conditions(diameters_mm=(GAUGE_DIAMETER_MM,), placement_mm=placement_mm,
                               n_theta=360, calibration=plan_covariance(rig)), gradient=False)
    unc = np.array([r["error_uncompensated_um"] for r in rows]) * 1e-3
    return {"rig": rig.name, "placement_mm": float(placement_mm), "calibrations": rows,
            "compensated": sigma_with_interval(err),
            "uncompensated": sigma_with_interval(unc),
            "model_plan_um": float(plan.sigma_R_cal_um[1]),
            "model_files_rms_um": float(np.sqrt(np.mean(
                [r["model_file_covariance_um"] ** 2 for r in rows])))}


def _model_shares(rig, placement_mm: float, uncertainty: dict | None, true_cal) -> dict:
    """The design model's shares for the same case (µm): noise alone, with the compensation,
    with the calibration's covariance."""
    try:
        from lts360.design.model import CalibrationCovariance, Conditions, evaluate
    except ImportError as exc:
        return {"error": f"model API not available: {exc}"}
    case = 1 if placement_mm > 0 else 0  # cases: centred, (+ρ, 0), (−ρ, 0), (0, +ρ), (0, −ρ)
    base = dict(diameters_mm=(GAUGE_DIAMETER_MM,), placement_mm=float(placement_mm),
                n_theta=360, compensation_diameter_mm=GAUGE_DIAMETER_MM, compensation_shots=1)
    space = DesignSpace.create(rig)
    try:
        noise = evaluate(space, None, Conditions(**base, compensate=False), gradient=False)
        comp = evaluate(space, None, Conditions(**base, compensate=True), gradient=False)
        # The simulation measures spreads: the total is the random shares' (the line-centre
        # bias the twin would leave is reported apart, not part of it).
        out = {"case": list(comp.cases[case]), "noise_um": float(noise.sigma_R_noise_um[case]),
               "compensation_um": float(comp.sigma_R_comp_um[case]),
               "calibration_um": None,
               "total_um": math.hypot(float(comp.sigma_R_noise_um[case]),
                                      float(comp.sigma_R_comp_um[case])),
               "bias_left_um": float(comp.bias_left_um[case])}
        if uncertainty is not None:
            planes = {m.name: m.n for m in true_cal.mirrors}
            planes["laser"] = true_cal.laser_plane[0]
            cov = CalibrationCovariance.from_uncertainty(uncertainty, planes,
                                                         source="calibration file")
            cal = evaluate(space, None, Conditions(**base, compensate=True, calibration=cov),
                           gradient=False)
            out["calibration_um"] = float(cal.sigma_R_cal_um[case])
            out["total_um"] = math.hypot(float(cal.sigma_R_noise_um[case]),
                                         float(cal.sigma_R_comp_um[case]),
                                         float(cal.sigma_R_cal_um[case]))
    except (AttributeError, TypeError) as exc:  # the model without the shares' fields
        return {"error": f"model API not available: {type(exc).__name__}: {exc}"}
    return out


def check_shares(rig, *, draws: int, spp: int, seed: int, placement_mm: float = 2.0,
                 calibration=None, scale: float = 1.0, progress: bool = False) -> dict:
    """The radius σ of the gauge moved to ``(placement_mm, 0)``, share by share: model and
    simulation side by side (µm).

    The gauge (Ø19.9987 mm) is rendered noise-free twice (thin lens, ``spp``): centred (the
    §4.4 reference) and moved.  Each draw (independent seeds for every image and calibration)
    simulates

    ``noise``         the moved gauge in a new noisy image (EMVA 1288 + speckle), true
                      calibration, no compensation;
    ``compensation``  a new noisy reference image → :func:`joint_view_offsets` → a new noisy
                      image of the moved gauge measured compensated with those offsets;
    ``calibration``   (with ``calibration``) the true calibration carrying the file's
                      ``uncertainty`` (the covariance is the file's, the nominal values the
                      truth's), :func:`sample_calibration`, compensated on the noise-free
                      reference, measuring the noise-free moved gauge compensated.

    Shares: noise = σ_noise; compensation = √(σ_comp² − σ_noise²) (approximate interval from
    Welch–Satterthwaite's degrees of freedom; not resolved when σ_comp ≤ σ_noise);
    calibration = σ_cal.  A paired estimate of the compensation share (the same noisy image
    measured with and without the offsets) is given beside it.

    Parameters
    ----------
    draws : int, >=3
    spp : int, >=1
    seed : int
        Root of every random stream (``np.random.SeedSequence(seed).spawn``).
    placement_mm : float, in [0, 10]
        Offset of the measured gauge along +x; the model's case ``(+ρ, 0)``.
    calibration : path, optional
        A calibration file with an ``uncertainty`` block.
    scale : float, in (0, 1]
        Image scale of the renders (tests); the file's covariance is applied as it is.
    progress : bool
        A progress bar on stderr.

    Raises
    ------
    ValueError
        A bad argument or calibration file (one line naming it).
    """
    from lts360.simulator.render import ensure_variant

    msg = share_args_error(draws, spp, placement_mm, calibration)
    if msg:
        raise ValueError(msg)
    if not (isinstance(scale, (int, float)) and 0.0 < scale <= 1.0):
        raise ValueError(f"scale: must be in (0, 1], got {scale!r}")
    unc, file_cal = file_uncertainty(calibration) if calibration is not None else (None, None)
    ensure_variant()
    t0 = time.perf_counter()
    sim = _simulate_shares(rig, draws=int(draws), spp=int(spp), seed=int(seed),
                           placement_mm=float(placement_mm), uncertainty=unc,
                           file_cal=file_cal, scale=float(scale), progress=progress)
    errs = sim["errors_mm"]
    stats = {k: sigma_with_interval(v) for k, v in errs.items() if len(v)}
    paired = errs["compensation"] - errs["compensation_paired_uncompensated"]
    shares = {"noise": dict(stats["noise"]),
              "compensation": _difference_share(stats["compensation"], stats["noise"]),
              "compensation_paired": sigma_with_interval(paired),
              "calibration": dict(stats["calibration"]) if "calibration" in stats else None}
    drawn_unc = (None if unc is None
                 else _oriented_uncertainty(unc, file_cal, sim["true_calibration"]))
    model = _model_shares(rig, float(placement_mm), drawn_unc, sim["true_calibration"])
    comparison = {}
    for share, key in (("noise", "noise_um"), ("compensation", "compensation_um"),
                       ("calibration", "calibration_um")):
        s = shares.get(share)
        m = model.get(key)
        comparison[share] = {"model_um": m, "simulated_um": None if s is None else s["sigma_um"],
                             "ratio_model_to_simulated":
                                 m / s["sigma_um"] if m is not None and s is not None
                                 and s["sigma_um"] else None}
    return {"rig": rig.name, "placement_mm": float(placement_mm), "draws": int(draws),
            "spp": int(spp), "seed": int(seed), "scale": float(scale),
            "calibration_file": None if calibration is None else str(calibration),
            "simulated": stats, "shares": shares, "model": model, "comparison": comparison,
            "noise_free": sim["noise_free"], "band_mm": sim["band_mm"],
            "radius_errors_um": {k: (1e3 * v).tolist() for k, v in errs.items() if len(v)},
            "seconds_render": sim["seconds_render"], "seconds_draws": sim["seconds_draws"],
            "seconds": time.perf_counter() - t0}


def _fmt_share(value, interval=None) -> str:
    if value is None:
        return "not resolved"
    text = f"{value:.2f}"
    if interval:
        text += f" [{interval[0]:.2f}, {interval[1]:.2f}]"
    return text + " µm"


def format_shares(r: dict) -> list[str]:
    """Per share: model vs simulation; last, a one-line summary."""
    lines = []
    sh, cmp_ = r["shares"], r["comparison"]
    for share in ("noise", "compensation", "calibration"):
        s = sh.get(share)
        if s is None:
            continue
        c = cmp_[share]
        m = "n/a" if c["model_um"] is None else f"{c['model_um']:.2f} µm"
        ratio = "" if c["ratio_model_to_simulated"] is None \
            else f", model/simulation {c['ratio_model_to_simulated']:.2f}"
        extra = ""
        if share == "compensation":
            p = sh["compensation_paired"]
            extra = f" (paired {_fmt_share(p['sigma_um'], p['sigma_95_um'])})"
        lines.append(f"  {share:<13} simulated {_fmt_share(s['sigma_um'], s['sigma_95_um'])}"
                     f"{extra}, model {m}{ratio}")
    if "error" in r["model"]:
        lines.append(f"  model: {r['model']['error']}")
    sim = r["simulated"]
    parts = [f"{k} σ {_fmt_share(v['sigma_um'])} (mean {v['mean_um']:+.2f} µm)"
             if v["mean_um"] is not None else f"{k}: nothing measured" for k, v in sim.items()
             if k != "compensation_paired_uncompensated"]
    c = sh["compensation"]
    lines.append(f"{r.get('source', r['rig'])} @ +{r['placement_mm']:g} mm: "
                 + "; ".join(parts)
                 + f"; shares noise {_fmt_share(sh['noise']['sigma_um'])}, compensation "
                 f"{_fmt_share(c['sigma_um'])}"
                 + ("" if sh["calibration"] is None
                    else f", calibration {_fmt_share(sh['calibration']['sigma_um'])}")
                 + f" ({r['draws']} draws, {r['seconds']:.0f} s)")
    return lines
