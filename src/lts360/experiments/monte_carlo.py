"""``lts360 study monte-carlo``: the uncertainty of the plug-gauge radius by the Monte Carlo
method of GUM Supplement 1 (JCGM 101:2008), beside a GUM (JCGM 100) uncertainty budget.

Measurand: the radius error Y = R_measured − R_nominal of the Ø19.9987 mm gauge (µm).

Inputs and their distributions (each drawn independently per trial):

==================  ==========================================================================
calibration         the estimated calibration drawn from its own covariance (Gaussian:
                    the intrinsics' jackknife covariance over the boards, or OpenCV's σ for
                    a calibration without one; mirror and laser planes from the LSQ /
                    jackknife covariance of ``lts360 calibrate``), :func:`sample_calibration`,
                    followed
                    — as in the lab — by a new §4.4 compensation measured with it on the
                    gauge at the reference placement (the first one; its image noise-free
                    unless the compensation input varies too)
compensation        the §4.4 reference image's own noise: the gauge at the reference placement
                    re-imaged with new sensor noise and a new speckle pattern, the view offsets
                    measured on it — one compensation's offsets carry that image's noise into
                    every later measurement (nominal: the noise-free reference); with
                    ``compensation_shots`` K, K such images fitted jointly
sensor noise        EMVA 1288 temporal noise redrawn (shot, read, quantisation)
speckle             a new speckle pattern (a new patch of surface under the line)
placement           one of ``placements`` pre-rendered gauge placements, uniform (offset in a
                    0.3 mm disc, tilt ≤ 0.3°): a discrete sample of the placement distribution
temperature         ΔT ~ U(−5, 5) K, steel α = 11.5e-6 /K: the gauge radius grows by α·R·ΔT
                    while its nominal value stays (added to Y; first order exact)
==================  ==========================================================================

Render once, perturb many: each placement is rendered once (noise-free radiance, at
:data:`PLACEMENT_SPP` samples a pixel); a trial redraws the speckle and the sensor noise on the
stored radiance, draws a calibration and reconstructs — nothing is re-rendered.  A stored
render's own noise is the same in every trial, so it is a bias of the study, not a spread:
at 16 spp the reference placement's render noise moved the nominal §4.4 offsets by 1.4–3.4 µm
(sd over render seeds; the true calibration, one placement), and one converged image measured
with that compensation read −10.3 … −11.5 µm against −8.7 / −8.9 µm with a 1024-spp
reference: a bias, not only a scatter; at 256 spp 0.6–0.8 µm and −8.0 … −8.8 µm (STUDIES.md).

Two procedures: a fixed number of trials M, or the adaptive procedure of JCGM 101 §7.9 —
batches of ``batch`` trials until twice the standard deviations of the batch means of the
mean, the standard uncertainty and both ends of the 95 % coverage interval are all below the
numerical tolerance δ (§7.9.2: δ = ½·10^l for u(y) written with ``n_dig`` significant digits).
The coverage interval is the probabilistically symmetric one (§7.7).  JCGM 101 (and DESIGN.md)
take batches of max(J, 10⁴) with J = ⌈100/(1−p)⌉; one trial here costs ~0.6 s of CPU (two
reconstructions and two twin renders, not a formula), so a batch of 10⁴ would take over an
hour on two cores — the default batch is 100 trials (``--batch``), the stopping rule
unchanged.

The §4.4 compensation is part of the measurement procedure, so every trial measures with a
compensated calibration, compensated the same way: the nominal calibration (the file given,
whatever view offsets it holds) is compensated once at the reference placement, a drawn one
anew (:func:`_compensate`).  Earlier versions of the study took, for the nominal trials, the offsets of
the file given — the command line's compensation, on a centred gauge imaged with realistic
noise — while drawn ones were compensated on the noise-free reference placement: the
calibration-only run's mean sat 9 µm from the others'.  That gap is one compensation's own
noise: the ``compensation`` input.

The study measures as a user of the rig would, as the plug-gauge study does, each step
switchable:

- ``master`` (default on; ``--no-master``: §4.4 alone, the paper's method): every
  compensation, nominal and drawn, is mastered with the gauge's known diameter
  (:func:`~lts360.recon.calibration.compensation.master_fit`: per view a radial offset too),
  so a drawn calibration's size error is absorbed;
- ``bias_model="twin"`` (default; ``--bias-model none``): every trial's section is corrected
  by its twin (:func:`lts360.twin.twin_corrected`, the code path of the plug-gauge study's
  :func:`~lts360.experiments.gauge_study.measure_gauge_image`), and a mastered compensation's
  reference shots too (:func:`lts360.twin.twin_corrected_raw`, as ``lts360 compensate``).

The twin is rendered anew for every trial by default (``twin_per="trial"``), with that
trial's calibration and from that trial's measured section: each drawn calibration has its
own twin (its own camera and mirrors), and a user's twin is shaped and exposed from the noisy
image.  The configurations of one draw share its drawn calibration, its reference shots
(imaged and measured once), one inverse plan and one sampling of the image (they differ only
by compensation, applied to the measured points afterwards:
:func:`~lts360.recon.triangulation.inverse.recompensated`) and one twin (one loaded scene,
moved to each surface); the twin's two corrections (its own section and the master's
reference shot) are about two thirds of a trial's CPU (BENCHMARKS.md).  The twin's samples are
keyed to the pixel and the seed (:class:`~lts360.simulator.keyed_sampler.KeyedSampler`):
with one seed for every trial each twin would draw nearly the same render noise, so a trial
whose every input varies renders its twin with a seed of its own (the twin's default seed in
the one-at-a-time runs, whose inputs do not include it).

``twin_per="placement"`` (``--twin-per placement``) computes each placement's correction once
per process instead, from its noise-free image and the nominal calibration
(:mod:`lts360.experiments.mc_measure`), and subtracts it in every trial: a quarter of the
CPU a trial (0.16 against 0.63 s on the 2-core VM, BENCHMARKS.md), but the correction's own
variation with the draw (its calibration, the noisy section it is shaped from, its render
noise) is left out of u(y).  On the same draws
(``benchmarks/bench_mc_twin.py``) the two differ by 0.54 µm rms in y (at most 1.8 µm over 24
draws) against a u(y) of 3.0 µm: for design sweeps and quick looks; the default for the
uncertainty one states.

With ``steps`` (default on) each trial of the full Monte Carlo also measures its image with
the other configurations of :data:`MC_STEPS` on the same draw (the same image, drawn
calibration and reference image): the summary's ``steps`` give the paper's method beside ours
and u(y) with and without the master.  The trial's own measurement before the twin's
correction is recorded too (``y_no_twin_um``; its master's shots stay twin-corrected).  The
one-at-a-time runs measure only the configuration.

Sensitivity: "one at a time" runs where only one input varies (the others at their nominal
value: the estimated calibration, no noise, no speckle, the first placement, ΔT = 0) give each
input's contribution u_i; the GUM budget combines them as √Σu_i² (independent inputs,
linear model) and is compared with the Monte Carlo u(y).  The speckle limit of laser
triangulation (Dorsch, Häusler, Herrmann, Appl. Opt. 33(7) 1994) for the same optics,
δz = C·λ / (2π·sin u_obs·sin θ), is compared with the per-point scatter of the speckle-only run.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np

from lts360.experiments.gauge_study import (
    DEFAULT_PLACEMENT_MM,
    DELTA_T_K,
    GAUGE_DIAMETER_MM,
    STEEL_ALPHA_PER_K,
    STEPS,
    _config_label,
    _step_key,
    check_calibration_rig,
    gauge_placements,
)
from lts360.experiments.mc_measure import (
    TWIN_PER,
    _calibration,
    _compensate,
    _grid,
    _noise_free_image,
    _nominal_calibration,
    _plan,
    _read,
    _uncompensated,
    measure,
    read_set,
    stored_render,
)
from lts360.experiments.runner import Trial, TrialOutput, plan_trials, run_study, study_pool
from lts360.folders import is_frame, read_frame_meta
from lts360.simulator.render import MAX_SPP

__all__ = ["INPUTS", "MC_STEPS", "mc_trial", "run_monte_carlo_study", "coverage_interval",
           "adaptive_stable", "dorsch_speckle_limit_um", "speckle_point_prediction_um",
           "format_mc"]

INPUTS = ("calibration", "compensation", "sensor_noise", "speckle", "placement", "temperature")
#: The configurations of the gauge study's :data:`~lts360.experiments.gauge_study.STEPS` each
#: trial of the full Monte Carlo also measures its image with (``steps``; the same draw: image,
#: calibration, reference image): the paper's method, the master, the master and the twin.
#: §4.4 + twin without the master is left out (one more twin render per trial): ``--no-master``
#: measures it as the study's configuration.
MC_STEPS = tuple(s for s in STEPS if s[0] in ("c44", "c44_master", "c44_master_twin"))
#: Samples per pixel of the placements' stored renders (module docstring: their render noise
#: is common to every trial; with the pixel support a 256-spp placement costs ~0.6 s).
PLACEMENT_SPP = 256


def coverage_interval(y: np.ndarray, p: float = 0.95) -> tuple[float, float]:
    """Probabilistically symmetric 100p % coverage interval (JCGM 101 §7.7)."""
    y = np.sort(np.asarray(y, float))
    M = len(y)
    q = int(round(p * M))
    r = int(round((M - q) / 2))
    lo = y[max(r - 1, 0)] if r >= 1 else y[0]
    hi = y[min(r + q - 1, M - 1)]
    return float(lo), float(hi)


def _tolerance(u: float, n_dig: int) -> float:
    """JCGM 101 §7.9.2: δ = ½·10^l with u written as c·10^l, c an n_dig-digit integer."""
    if not u > 0:
        return math.inf
    l = math.floor(math.log10(u)) - (n_dig - 1)
    return 0.5 * 10.0**l


def adaptive_stable(batches: list[np.ndarray], n_dig: int = 2, p: float = 0.95) -> tuple[bool, dict]:
    """JCGM 101 §7.9.4 stopping rule over the batches so far."""
    h = len(batches)
    stats = np.array([[b.mean(), b.std(ddof=1), *coverage_interval(b, p)] for b in batches])
    u = float(np.concatenate(batches).std(ddof=1))
    delta = _tolerance(u, n_dig)
    if h < 2:
        return False, {"h": h, "delta": delta}
    s = stats.std(axis=0, ddof=1) / math.sqrt(h)
    return bool(np.all(2 * s <= delta)), {"h": h, "delta": delta, "2s": (2 * s).tolist()}


def dorsch_speckle_limit_um(rig) -> dict:
    """δz of Dorsch, Häusler and Herrmann (1994) for the rig's optics (µm), per point, at the
    direct view's aim: ``C λ / (2π sin u sin θ)`` with ``C = 1`` — the contrast of fully
    developed speckle as the lens images it, not the pixel-integrated contrast (also returned,
    as ``pixel_contrast``, for the simulator's model) — and ``sin u`` the aperture seen from
    the object axis.  The per-view figures over the whole section are in
    :func:`speckle_point_prediction_um`."""
    from lts360.simulator.speckle import speckle_contrast_theory

    cam = rig.camera
    m = cam.focal_length_mm / (cam.focus_distance_mm - cam.focal_length_mm)
    c_px = speckle_contrast_theory(cam.pixel_pitch_um, rig.laser.wavelength_nm, cam.f_number,
                                   magnification=m)
    z_obj = float(np.linalg.norm(cam.center_mm))  # camera to the object axis
    sin_u = (cam.focal_length_mm / cam.f_number) / (2.0 * z_obj)
    theta = math.radians(rig.design.alpha_deg)
    lam_um = rig.laser.wavelength_nm * 1e-3
    return {"contrast": 1.0, "pixel_contrast": c_px, "sin_u_obs": sin_u,
            "triangulation_deg": rig.design.alpha_deg,
            "delta_z_um": lam_um / (2 * math.pi * sin_u * math.sin(theta))}


def speckle_point_prediction_um(rig, diameter_mm: float = 19.9987) -> dict:
    """Per-point speckle σ_r (rms over the measured section, µm) that the design model
    (:mod:`lts360.design`) predicts: ``pixel`` — the simulator's speckle (pixel-integrated
    contrast, the threshold centroid) — and ``dorsch`` — the optical limit, ``C = 1`` and each
    view's own aperture."""
    from lts360.design.model import Conditions, evaluate
    from lts360.design.params import DesignSpace

    space = DesignSpace.create(rig)
    return {sk: float(evaluate(space, None, Conditions(diameters_mm=(diameter_mm,), n_theta=360,
                                                       speckle=sk),
                               gradient=False).speckle_rms_um[0])
            for sk in ("pixel", "dorsch")}


@functools.lru_cache(maxsize=64)
def _offset_mm(frame_dir: str) -> float:
    """Distance of a rendered placement's axis from the rig's axis (from its frame.json)."""
    from lts360.scenes.objects import build_object

    meta = read_frame_meta(frame_dir)
    pl = build_object(meta["object"]["spec"]).placement
    return float(math.hypot(pl.x_mm, pl.y_mm))


@functools.lru_cache(maxsize=16)
def _nominal_radii(frame_dir: str, cal_path: str, renders: str, rig_name: str,
                   theta_step_deg: float, compensate: bool = True,
                   placement_mm: float = DEFAULT_PLACEMENT_MM, master: bool = False,
                   bias_model: str = "none") -> dict:
    """Per-view radii of a placement without noise or speckle (the speckle run's reference;
    before any twin correction, as the speckle run's own radii)."""
    from lts360.recon.triangulation.inverse import inverse_triangulate

    img = _noise_free_image(frame_dir, rig_name)
    cal = (_nominal_calibration(cal_path, renders, rig_name, theta_step_deg, placement_mm,
                                master, bias_model) if compensate else _uncompensated(cal_path))
    res = inverse_triangulate(img, cal, _grid(theta_step_deg, placement_mm),
                              compensate=compensate)
    return {n: v.r_mm for n, v in res.views.items()}


def _trial_calibration(p: dict, vary: set, seeds, *, compensate: bool, master: bool,
                       bias_model: str, memo: dict | None = None, frozen: str | None = None):
    """The calibration a trial measures with: drawn or nominal, compensated as configured.

    ``memo``: a dict the calls of one trial share (the same ``p``, ``vary``, ``seeds``): the
    drawn calibration and its reference shots are made once for all its configurations."""
    from lts360.recon.calibration.uncertainty import sample_calibration

    pl_mm = float(p.get("placement_mm", DEFAULT_PLACEMENT_MM))
    step = float(p["theta_step_deg"])
    if not compensate:  # measured without the §4.4 compensation
        cal = _uncompensated(p["calibration"])
        if "calibration" in vary:
            cal = sample_calibration(cal, np.random.default_rng(seeds[2]))
        return cal
    if vary & {"calibration", "compensation"}:
        # A new calibration is followed by a new §4.4 compensation, as in the lab: measure
        # the gauge at the reference placement with it and put the views on one circle.
        memo = {} if memo is None else memo
        if "drawn" not in memo:
            cal = _calibration(p["calibration"])
            if "calibration" in vary:
                cal = sample_calibration(cal, np.random.default_rng(seeds[2]))
            memo["drawn"] = cal
        return _compensate(memo["drawn"], p["renders"], p["rig"], step,
                           noise_seed=int(seeds[4]) if "compensation" in vary else None,
                           shots=int(p.get("compensation_shots", 1)), placement_mm=pl_mm,
                           master=master, bias_model=bias_model if master else "none",
                           memo=memo, frozen=frozen)
    return _nominal_calibration(p["calibration"], p["renders"], p["rig"], step, pl_mm, master,
                                bias_model if master else "none")  # the same procedure, once


def _radius_error_um(result, dT: float) -> tuple[float, float, int]:
    """Y (µm) of a measured section — circle fit of every view's valid points, minus the
    nominal radius, plus the gauge's thermal growth — its point scatter (µm) and points."""
    from lts360.geometry.fit import fit_circle

    pts = np.concatenate([v.points_meas_mm[v.valid, :2] for v in result.views.values()])
    if len(pts) < 10:
        return np.nan, np.nan, int(len(pts))
    r0 = GAUGE_DIAMETER_MM / 2.0
    fit = fit_circle(pts)
    r = np.hypot(*(pts - fit.center_mm).T)
    y = (fit.radius_mm - r0) * 1e3 + STEEL_ALPHA_PER_K * r0 * dT * 1e3
    return float(y), float(r.std() * 1e3), int(len(pts))


def _twin_seed(vary: set, seeds) -> int | None:
    """The twin's render seed of a trial whose every input varies (its render noise drawn
    too: a stream of its own from the trial's seeds); ``None`` (the twin's default seed) in a
    one-at-a-time run."""
    if vary != set(INPUTS):
        return None
    return int(np.random.SeedSequence([int(seeds[0]), 7717]).generate_state(1)[0])


def vary_set(vary: str) -> set:
    """The inputs a trial's ``vary`` names: ``all``, ``none`` (the nominal measurement), one
    of :data:`INPUTS`, or several joined by ``+`` (``calibration+placement``: those vary
    together, to see whether their effects add in quadrature as the one-at-a-time budget
    assumes)."""
    if vary == "all":
        return set(INPUTS)
    if vary == "none":
        return set()
    names = set(str(vary).split("+"))
    if not names <= set(INPUTS):
        raise ValueError(f"vary: unknown input(s) {sorted(names - set(INPUTS))}; "
                         f"use all or {', '.join(INPUTS)} (joined by +)")
    return names


def mc_trial(trial: Trial) -> TrialOutput:
    """One Monte Carlo draw (see the module docstring); ``params['vary']`` names the inputs
    that vary (:func:`vary_set`).  ``params``: ``compensate``, ``master``,
    ``bias_model`` (the configuration measured; defaults: §4.4 alone, as earlier studies),
    ``twin_per`` (:data:`~lts360.experiments.mc_measure.TWIN_PER`; default ``"trial"``) and
    ``steps`` (also each of :data:`MC_STEPS` on the same draw: ``y_<key>_um``)."""
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    p = trial.params
    pl_mm = float(p.get("placement_mm", DEFAULT_PLACEMENT_MM))
    vary = vary_set(p["vary"])
    rng = np.random.default_rng(trial.seed)
    seeds = rng.integers(0, 2**31, size=5)
    k = int(rng.integers(int(p["placements"]))) if "placement" in vary else 0
    frame_dir = str(Path(p["renders"]) / f"placement_{k:02d}")
    step = float(p["theta_step_deg"])
    compensate = bool(p.get("compensate", True))
    master = bool(p.get("master", False)) and compensate
    bias_model = p.get("bias_model", "none")
    if bias_model not in ("none", "twin"):
        raise ValueError(f"bias_model must be none or twin, got {bias_model!r}")
    twin_per = p.get("twin_per", "trial")
    if twin_per not in TWIN_PER:
        raise ValueError(f"twin_per must be one of {', '.join(TWIN_PER)}, got {twin_per!r}")
    grid = _grid(step, pl_mm)
    # the draw's calibration, plan and reference shots, shared by its steps; its images drawn
    # on the pixels its plan reads (read_set)
    memo: dict = {"read_set": read_set(p["calibration"], step, pl_mm)}
    if (twin_seed := _twin_seed(vary, seeds)) is not None:
        memo["twin_seed"] = twin_seed
    frozen = ((frame_dir, p["calibration"], p["renders"], p["rig"], step, pl_mm)
              if twin_per == "placement" else None)
    cal_kw = dict(memo=memo, frozen=p["calibration"] if frozen else None)
    cal = _trial_calibration(p, vary, seeds, compensate=compensate, master=master,
                             bias_model=bias_model, **cal_kw)
    read = _read(memo, _plan(cal, grid, memo))
    image, _, _ = sensor_image(load_rig(p["rig"]), stored_render(frame_dir),
                               noise="realistic" if "sensor_noise" in vary else "none",
                               seed=int(seeds[0]), speckle="speckle" in vary,
                               speckle_seed=int(seeds[1]), read=read)
    out, plain, twin_bias = measure(image, cal, grid, bias_model, memo, frozen)
    offset = _offset_mm(frame_dir)
    dT = float(np.random.default_rng(seeds[3]).uniform(-DELTA_T_K, DELTA_T_K)) \
        if "temperature" in vary else 0.0
    y, point_std, n = _radius_error_um(out, dT)
    values = {"y_um": y, "point_std_um": point_std, "n_points": n, "placement": k,
              "delta_T_K": dT, "offset_mm": offset}
    if bias_model == "twin":  # the same measurement before the twin's correction
        values["y_no_twin_um"] = _radius_error_um(plain, dT)[0]
        values["twin_bias_um"] = twin_bias
    if p["vary"] == "speckle":  # per-point scatter caused by speckle alone (vs. no speckle)
        nominal = _nominal_radii(frame_dir, p["calibration"], p["renders"], p["rig"], step,
                                 compensate, pl_mm, master, bias_model)
        diffs = np.concatenate([plain.views[n].r_mm - nominal[n] for n in plain.views])
        values["speckle_point_std_um"] = float(np.nanstd(diffs) * 1e3)
    if p.get("steps"):
        ours = _step_key(compensate, master, bias_model)
        for key, _, (comp, mast, bias) in MC_STEPS:
            if key == ours:
                values[f"y_{key}_um"] = y
                continue
            c = _trial_calibration(p, vary, seeds, compensate=comp, master=mast, bias_model=bias,
                                   **cal_kw)
            values[f"y_{key}_um"] = _radius_error_um(
                measure(image, c, grid, bias, memo, frozen)[0], dT)[0]
    return TrialOutput(values=values)


def _render_placements(out: Path, n: int, *, rig: str, seed: int, spp: int, say,
                       placement_mm: float = DEFAULT_PLACEMENT_MM) -> Path:
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame, write_frame
    from lts360.simulator.render import ensure_variant

    root = out / ("renders" if placement_mm == DEFAULT_PLACEMENT_MM
                  else f"renders-{placement_mm:g}mm")
    ensure_variant()
    for k, params in enumerate(gauge_placements(n, seed, offset_mm=placement_mm)):
        d = root / f"placement_{k:02d}"
        if is_frame(d):
            _check_stored(d, spp)
            continue
        say(f"rendering placement {k + 1}/{n}: {params['spec']}")
        frame = simulate_frame(load_rig(rig), build_object(params["spec"]), spp=spp,
                               seed=seed * 100 + k, noise="none")
        write_frame(d, frame)
    return root


def _check_stored(frame_dir: Path, spp: int) -> None:
    """Refuse a stored placement rendered at another sample count than asked: its render
    noise, common to every trial, would differ from what the run says."""
    had = (read_frame_meta(frame_dir).get("render") or {}).get("spp")
    if had is not None and int(had) != int(spp):
        raise ValueError(f"{frame_dir} was rendered at {had} spp, this run asks {spp}: give "
                         f"--spp {had}, or another --out")


def _batch_seed(seed: int, name: str, h: int) -> int:
    key = [int(seed), sum(map(ord, name)), h]
    return int(np.random.SeedSequence(key).generate_state(1)[0])


def _run_batches(out: Path, name: str, base: dict, *, seed: int, batch: int, max_batches: int,
                 adaptive: bool, n_dig: int, workers, dask_address, pool,
                 say) -> tuple[np.ndarray, dict]:
    batches, info = [], {}
    for h in range(max_batches):
        trials = plan_trials([dict(base)] * batch, _batch_seed(seed, name, h))
        ds = run_study(out / name / f"batch_{h:03d}", trials, mc_trial, name=f"{name}-{h}",
                       workers=workers, dask_address=dask_address, progress=True, pool=pool)
        y = ds["y_um"].values
        batches.append(y[np.isfinite(y)])
        if adaptive:
            stable, info = adaptive_stable(batches, n_dig)
            say(f"{name}: {sum(map(len, batches))} trials, δ = {info['delta']:.3g} µm, "
                f"stable: {stable}")
            if stable:
                break
    return np.concatenate(batches), info


def _run_all_batches(out: Path, base: dict, kw: dict, *, trials: int, batch: int,
                     adaptive: bool, n_dig: int, steps: bool, compensate: bool, master: bool,
                     bias_model: str, sensitivity_trials: int) -> tuple[np.ndarray, dict, dict]:
    """The full Monte Carlo's batches and the one-input-at-a-time runs: (y, summary, budget)."""
    full = dict(base, vary="all", steps=True) if steps else dict(base, vary="all")
    y, info = _run_batches(out, "mc", full, batch=batch,
                           max_batches=(10_000 if adaptive else max(1, math.ceil(trials / batch))),
                           adaptive=adaptive, n_dig=n_dig, **kw)
    lo, hi = coverage_interval(y)
    summary = {"M": int(len(y)), "mean_um": float(y.mean()), "u_um": float(y.std(ddof=1)),
               "interval95_um": [lo, hi], "adaptive": adaptive, "adaptive_info": info,
               "configuration": _config_label(compensate, master and compensate, bias_model),
               "ours": _step_key(compensate, master and compensate, bias_model) or ""}
    budget = {}
    for name in INPUTS:
        if name == "compensation" and not compensate:
            continue
        yi, _ = _run_batches(out, f"only-{name}", dict(base, vary=name), batch=sensitivity_trials,
                             max_batches=1, adaptive=False, n_dig=n_dig, **kw)
        budget[name] = {"u_um": float(yi.std(ddof=1)), "mean_um": float(yi.mean()),
                        "M": int(len(yi))}
    return y, summary, budget


def run_monte_carlo_study(out_dir, *, calibration, trials: int = 1000, adaptive: bool = False,
                          batch: int = 100, n_dig: int = 2, sensitivity_trials: int = 50,
                          placements: int = 8, seed: int = 0, rig: str = "paper",
                          spp: int = PLACEMENT_SPP,
                          theta_step_deg: float = 0.5, workers: int | None = None,
                          dask_address: str | None = None, compensate: bool = True,
                          compensation_shots: int = 1, master: bool = True,
                          bias_model: str = "twin", steps: bool = True,
                          placement_mm: float = DEFAULT_PLACEMENT_MM, twin_per: str = "trial",
                          say=print) -> dict:
    """Run the study (see the module docstring); returns the summary written to summary.json.

    ``spp``: samples per pixel of the placements' renders (:data:`PLACEMENT_SPP`; renders
    already in ``out_dir`` at another count are refused).

    ``placement_mm``: the placements are drawn in a disc of that radius about the axis (their
    renders kept in ``renders/``, or ``renders-Rmm/`` for another radius); the summary's
    ``by_offset`` gives the trials' mean result per placement against its distance from the
    axis.

    ``compensate=False``: every trial measures without the §4.4 compensation (the view
    offsets of ``calibration`` are ignored) and the ``compensation`` input is left out.
    ``compensation_shots``: images of the reference placement each compensation is fitted
    to (jointly, :func:`lts360.recon.calibration.compensation.joint_view_offsets`); the ``compensation``
    input's spread falls as ``1/√shots``.  ``master`` (default on): every compensation is
    mastered with the gauge's known diameter (needs ``compensate``).  ``bias_model``
    ``"twin"`` (default): every trial's section corrected by its twin (and, mastered, the
    master's reference shots too).  ``steps``: each trial of the full Monte Carlo also
    measured with each of :data:`MC_STEPS` (the summary's ``steps``: the paper's method beside
    ours on the same draws).  ``twin_per``: the twin rendered for each ``"trial"`` (default),
    or each ``"placement"``'s correction frozen (:mod:`lts360.experiments.mc_measure`)."""
    if bias_model not in ("none", "twin"):
        raise ValueError(f"bias_model must be none or twin, got {bias_model!r}")
    if twin_per not in TWIN_PER:
        raise ValueError(f"twin_per must be one of {', '.join(TWIN_PER)}, got {twin_per!r}")
    if not 1 <= int(compensation_shots) <= 100:
        raise ValueError(f"compensation_shots must be in [1, 100], got {compensation_shots}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not 0 <= placement_mm <= 10:
        raise ValueError(f"placement_mm must be in [0, 10], got {placement_mm}")
    if isinstance(spp, bool) or not 1 <= int(spp) <= MAX_SPP:
        raise ValueError(f"spp must be in [1, {MAX_SPP}], got {spp}")
    check_calibration_rig(calibration, rig)
    if bias_model == "twin":  # refused in one line, before any render, without its optics
        from lts360.recon.model import load_calibration
        from lts360.twin.rig import twin_design

        twin_design(load_calibration(calibration))
    renders = _render_placements(out, placements, rig=rig, seed=seed, spp=spp, say=say,
                                 placement_mm=float(placement_mm))
    base = {"calibration": str(Path(calibration).resolve()), "renders": str(renders.resolve()),
            "placements": placements, "rig": rig, "theta_step_deg": theta_step_deg,
            "placement_mm": float(placement_mm),
            "compensate": bool(compensate), "compensation_shots": int(compensation_shots)}
    # only when on: the trials of earlier studies (§4.4 alone) keep their parameters
    if int(spp) != 16:  # a trial says which renders it measured (16 spp: the studies before
        base["spp"] = int(spp)  # c2d20ad, whose trials do not record it)
    if master and compensate:
        base["master"] = True
    if bias_model == "twin":
        base["bias_model"] = "twin"
        if twin_per != "trial":
            base["twin_per"] = twin_per
    if workers is None and dask_address is None:
        workers = 2
    with study_pool(workers, dask_address) as pool:  # one pool for every batch of the study
        kw = dict(seed=seed, workers=workers, dask_address=dask_address, pool=pool, say=say)
        y, summary, budget = _run_all_batches(out, base, kw, trials=trials, batch=batch,
                                              adaptive=adaptive, n_dig=n_dig, steps=steps,
                                              compensate=compensate, master=master,
                                              bias_model=bias_model,
                                              sensitivity_trials=sensitivity_trials)
    summary["budget"] = budget
    summary["gum_u_um"] = float(math.sqrt(sum(b["u_um"] ** 2 for b in budget.values())))
    summary["ranking"] = sorted(budget, key=lambda k: -budget[k]["u_um"])
    from lts360.scenes.rig_io import load_rig

    summary["dorsch"] = dorsch_speckle_limit_um(load_rig(rig))
    summary["speckle_model_point_um"] = speckle_point_prediction_um(load_rig(rig))
    import xarray as xr

    sp = xr.open_dataset(out / "only-speckle" / "batch_000" / "results.nc")
    summary["speckle_point_std_um"] = float(np.nanmean(sp["speckle_point_std_um"].values))
    sp.close()
    summary["placement_mm"] = float(placement_mm)
    summary["twin_per"] = twin_per if bias_model == "twin" else None
    summary["by_offset"] = _by_offset(sorted((out / "mc").glob("batch_*/results.nc")))
    summary["steps"] = _steps(sorted((out / "mc").glob("batch_*/results.nc")))
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _plot(y, summary, out / "monte-carlo.png")
    return summary


def _steps(paths) -> dict:
    """Per configuration of :data:`MC_STEPS` the full Monte Carlo measured every draw with
    (and, with the twin, ours before the twin's correction): M, mean, u(y), 95 % interval."""
    import xarray as xr

    cols = {key: label for key, label, _ in MC_STEPS}
    cols["no_twin"] = "ours, before the twin's correction"
    vals: dict[str, list] = {}
    for path in paths:
        with xr.open_dataset(path) as ds:
            for key in cols:
                name = "y_no_twin_um" if key == "no_twin" else f"y_{key}_um"
                if name in ds:
                    vals.setdefault(key, []).append(np.asarray(ds[name].values, float))
    out = {}
    for key, parts in vals.items():
        y = np.concatenate(parts)
        y = y[np.isfinite(y)]
        if y.size > 1:
            lo, hi = coverage_interval(y)
            out[key] = {"label": cols[key], "M": int(y.size), "mean_um": float(y.mean()),
                        "u_um": float(y.std(ddof=1)), "interval95_um": [lo, hi]}
    return out


def _by_offset(paths) -> list[dict]:
    """Per rendered placement of the full Monte Carlo: its distance from the axis, the trials
    that drew it and their mean and standard deviation of y (µm), by increasing distance."""
    import xarray as xr

    off, yy = [], []
    for path in paths:
        with xr.open_dataset(path) as ds:
            if "offset_mm" not in ds:
                return []
            off.append(np.asarray(ds["offset_mm"].values, float))
            yy.append(np.asarray(ds["y_um"].values, float))
    if not off:
        return []
    off, yy = np.concatenate(off), np.concatenate(yy)
    rows = []
    for o in np.unique(np.round(off, 6)):
        m = np.isclose(off, o, atol=1e-6) & np.isfinite(yy)
        if m.any():
            rows.append({"offset_mm": float(o), "n": int(m.sum()), "mean_um": float(yy[m].mean()),
                         "std_um": float(yy[m].std(ddof=1)) if m.sum() > 1 else None})
    return rows


def _plot(y, summary, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].hist(y, bins=max(10, int(math.sqrt(len(y)))), density=True, color="0.6")
    lo, hi = summary["interval95_um"]
    for v in (lo, hi):
        ax[0].axvline(v, color="r", ls="--")
    xs = np.linspace(y.min(), y.max(), 200)
    m, u = summary["mean_um"], summary["gum_u_um"]
    ax[0].plot(xs, np.exp(-0.5 * ((xs - m) / u) ** 2) / (u * math.sqrt(2 * math.pi)), "b-",
               label=f"GUM: N({m:.1f}, {u:.1f}²)")
    ax[0].set_xlabel("radius error Y (µm)")
    ax[0].set_title(f"Monte Carlo, M = {summary['M']}; 95 % interval [{lo:.1f}, {hi:.1f}] µm")
    ax[0].legend()
    names = summary["ranking"]
    ax[1].barh(names[::-1], [summary["budget"][n]["u_um"] for n in names[::-1]])
    ax[1].set_xlabel("u_i (µm), one input at a time")
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def format_mc(s: dict) -> str:
    lines = [f"Monte Carlo (GUM-S1){', ' + s['configuration'] if s.get('configuration') else ''}"
             f": M = {s['M']}, y = {s['mean_um']:+.2f} µm, "
             f"u(y) = {s['u_um']:.2f} µm, 95 % interval [{s['interval95_um'][0]:+.2f}, "
             f"{s['interval95_um'][1]:+.2f}] µm",
             f"GUM budget (one input at a time, √Σu_i²): u_c = {s['gum_u_um']:.2f} µm"]
    if s.get("twin_per") == "placement":
        lines.insert(1, "twin: each placement's correction frozen (noise-free, nominal "
                        "calibration): its variation with the draw is not in u(y)")
    for name in s["ranking"]:
        b = s["budget"][name]
        lines.append(f"  {name:14s} u_i = {b['u_um']:7.2f} µm  (mean {b['mean_um']:+.2f}, M = {b['M']})")
    d = s["dorsch"]
    if s.get("steps"):
        lines.append("each configuration on the same draws: mean y, u(y), 95 % interval (µm)")
        for key, t in s["steps"].items():
            mark = "  <- lts360" if key == s.get("ours") else ""
            lines.append(f"  {t['label']:36s} {t['mean_um']:+7.2f} {t['u_um']:6.2f}  "
                         f"[{t['interval95_um'][0]:+.2f}, {t['interval95_um'][1]:+.2f}]  "
                         f"M = {t['M']}{mark}")
    if s.get("by_offset"):
        lines.append(f"against the distance from the axis (placements within "
                     f"{s.get('placement_mm', DEFAULT_PLACEMENT_MM):g} mm): offset, trials, mean y")
        for b in s["by_offset"]:
            lines.append(f"  {b['offset_mm']:.3f} mm  {b['n']:5d}  {b['mean_um']:+7.2f} µm")
    lines.append(f"speckle limit (Dorsch et al. 1994), per point at the direct view's aim: "
                 f"δz = {d['delta_z_um']:.1f} µm (C = {d['contrast']:.3g}, sin u = "
                 f"{d['sin_u_obs']:.4f}, θ = {d['triangulation_deg']:.0f}°)")
    pm = s.get("speckle_model_point_um")
    if pm:
        lines.append(f"speckle per point, rms over the section (design model): "
                     f"{pm['pixel']:.1f} µm (the simulator's pixel speckle, contrast "
                     f"{d.get('pixel_contrast', float('nan')):.3f}, threshold centroid), "
                     f"{pm['dorsch']:.1f} µm (Dorsch's optical limit, each view's aperture)")
    lines.append(f"simulated speckle-only point scatter {s['speckle_point_std_um']:.1f} µm")
    return "\n".join(lines)
