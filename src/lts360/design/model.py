"""The differentiable model of a rig: stripe images, radius sensitivity, line noise, coverage.

From the continuous design parameters (:mod:`lts360.design.params`) the model computes, in
Dr.Jit (LLVM, double precision, reverse-mode AD), for each *case* (a section radius and a
placement of its centre) and each θ of a uniform grid:

* per view (direct, left, right; the double reflections left-right and right-left for the
  constraint on multiple reflections) the stripe's image position ``u(θ)`` — paper Eq. 4,
  ``g = P · T_π · G``, with the base rig's Brown distortion — exactly as
  :func:`lts360.geometry.camera.project_points` computes it;
* the Jacobians ``∂u/∂r``, ``∂u/∂θ``, ``∂u/∂z`` through ``T_π`` and the projection, and from
  them the sensitivity ``∂r/∂n = |∂u/∂θ| / |∂u/∂θ × ∂u/∂r|`` of the radius to a shift ``n`` of
  the line across itself (the measurement searches along the image of the radial line);
* the line's image width: the sheet's Gaussian σ at the illuminating path length
  (``w(L) = w0 √(1 + ((L − L_w)/z_R)²)``, σ = w/2) projected across the line, ⊕ thin-lens
  defocus (blur-circle diameter ``b = A f |Z − s| / (Z (s − f))``, σ = b/4) ⊕ diffraction
  (0.42 λN) ⊕ the pixel box (1/12 px²);
* the line-position noise across the line (px) of the paper's detector, the centroid of
  ``I − t`` over the run above the threshold ``t`` (10 % of full scale, relative to each
  point's peak): speckle (see :data:`SPECKLE_MODELS`), the sensor's shot and read noise with
  quantisation (EMVA 1288 parameters; the exposure is the simulator's auto-exposure, the
  brightest stripe at 80 % of the full well), pixel locking (:mod:`lts360.design.locking`),
  independent and added in quadrature;
* the per-point radius σ, and the σ of the radius after the circle fit (a least-squares fit
  of ``r_i = R + a cos θ_i + b sin θ_i`` to every measured point of every single view, the
  points' errors correlated over ``CORRELATION_PX`` of stripe length);
* smooth coverage: every constraint of :func:`lts360.scenes.coverage.coverage` (the path meets
  each mirror inside its rectangle on its reflecting side, unoccluded by the object cylinder or
  another mirror; incidence limit for camera and laser; image bounds with margin; the laser
  fan), each a smooth step of its margin, multiplied (``measured``, which tends to coverage()'s
  as the sharpness grows); then the peak detector's threshold (``detected``: the line's peak,
  under the auto-exposure, above 1.25 × the 10 %-of-full-scale threshold), which loses dim
  and strongly defocused views.  The hard coverage is computed beside it from the rig itself;
* the §4.4 compensation's share and the calibration's (:mod:`lts360.design.shares`; the
  calibration's covariance from a file, or predicted per design from the board plan,
  :mod:`lts360.design.calib_covariance`), added in quadrature to the image's own;
* the line-centre bias of the curved section (the sheet's thickness and the image's blur,
  in closed form, :mod:`lts360.design.bias`), and what a master and the twin leave of it: a
  share of the radius' uncertainty.

Where the model stops (not modelled): the coupling of the calibration's stages (its planes
absorb its K error; the blocks are drawn independently); saturation and the exposure range;
speckle correlated between pixels (speckle larger than a pixel); the line-centre bias of a
strongly defocused view beyond the blurred curve's (docs/design.md); glossy materials (the
surface is white Lambertian); ambient light.  Every length in mm, angles in radians.

The model runs in stages, one module each: :mod:`~lts360.design.laser`,
:mod:`~lts360.design.camera`, :mod:`~lts360.design.noise`, :mod:`~lts360.design.calib_share`
and :mod:`~lts360.design.coverage`, on the elements of :mod:`~lts360.design.elements`, with
the Dr.Jit back end of :mod:`~lts360.design.backend`; this module holds the conditions, the
result, and the recorded (``dr.freeze``) evaluation.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from lts360.design.backend import DrJitOps
from lts360.design.bias import BIAS_MODELS, bias_stage
from lts360.design.calib_covariance import CalibrationPlan
from lts360.design.calib_share import plan_covariance_at, shares_stage
from lts360.design.camera import Distortion, line_stage, rig_geometry, view_stage
from lts360.design.coverage import coverage_stage
from lts360.design.elements import Elements
from lts360.design.laser import laser_stage
from lts360.design.noise import (
    CORRELATION_PX,
    SPECKLE_MODELS,
    exposure_reference,
    noise_stage,
    pixel_speckle_contrast,
)
from lts360.design.params import PARAMETERS, DesignError, DesignSpace
from lts360.design.shares import CalibrationCovariance
from lts360.scenes.coverage import mirror_sequences, view_name

__all__ = ["Conditions", "Evaluation", "evaluate", "evaluate_batch", "pixel_speckle_contrast",
           "plan_covariance_at", "CalibrationCovariance",
           "SPECKLE_MODELS", "CORRELATION_PX"]

@dataclasses.dataclass(frozen=True)
class Conditions:
    """What a design is evaluated for.

    Attributes
    ----------
    diameters_mm : tuple of float
        Section diameters (the objective is the worst of them).
    placement_mm : float, >=0
        Offset of the section centre from the axis; > 0 adds the four placements
        ``(±ρ, 0)``, ``(0, ±ρ)`` to the centred one.
    n_theta : int
        θ samples per case of the model's grid (uniform on [−π, π), as coverage()).
    theta_step_meas_deg : float
        θ step of the measurement (how many points the circle fit has).
    max_incidence_deg, margin_px
        As :func:`lts360.scenes.coverage.coverage`.
    sharpness : float, >0
        Sigmoid sharpness: widths 0.5/k mm, 1/k px and 0.01/k in cosine.
    speckle : str
        One of :data:`SPECKLE_MODELS`.
    min_coverage_deg, min_overlap_deg, max_multi_reflection_pct
        Constraints (penalties): single-view coverage, direct/mirror and mirror/mirror overlap,
        the share of the section also seen through both mirrors.
    penalty_um_per_deg2 : float
        Weight of a squared shortfall (µm of U per deg² of missing coverage or overlap).
    compensate : bool
        The measurement applies the §4.4 compensation (one circle and a translation per mirror
        view fitted on a reference image); its own noise then adds to every case's radius
        (:mod:`lts360.design.shares`), and it absorbs the calibration's view translations.
    compensation_diameter_mm, compensation_shots : float, int
        The reference: a centred round section of this diameter (the plug gauge), imaged
        ``compensation_shots`` times and fitted jointly.
    master : bool
        The compensation's reference is a master of known diameter (``lts360 compensate
        --master-diameter-mm``): a radial offset per view is fitted beside the translations,
        which removes each view's line-centre bias at the master's diameter
        (:mod:`lts360.design.bias`); the compensation's noise share is then the mastered fit's
        (:func:`lts360.design.shares.compensation_shares`).
    bias_model : str
        ``"twin"`` (the measurement removes the line-centre bias with its digital twin; it
        leaves :data:`lts360.design.bias.TWIN_RESIDUAL_FRACTION` of it) or ``"none"``.  What
        is left of the bias is a share of ``sigma_R_um``.
    calibration : CalibrationCovariance, CalibrationPlan or None
        The calibration's covariance (fixed), or a calibration plan whose covariance the
        model predicts for every design (:class:`lts360.design.calib_covariance.CalibrationPlan`);
        its share of the radius is added (None: a perfectly calibrated rig).
    """

    diameters_mm: tuple = (20.0,)
    placement_mm: float = 0.0
    n_theta: int = 180
    theta_step_meas_deg: float = 0.25
    max_incidence_deg: float = 80.0
    margin_px: float = 0.0
    sharpness: float = 1.0
    speckle: str = "pixel"
    min_coverage_deg: float = 359.0
    min_overlap_deg: float = 5.0
    max_multi_reflection_pct: float = 0.0
    penalty_um_per_deg2: float = 1.0
    compensate: bool = True
    compensation_diameter_mm: float = 19.9987
    compensation_shots: int = 1
    master: bool = False
    bias_model: str = "twin"
    calibration: CalibrationCovariance | None = None

    def __post_init__(self) -> None:
        d = tuple(float(v) for v in np.atleast_1d(self.diameters_mm))
        object.__setattr__(self, "diameters_mm", d)
        if not d or not all(math.isfinite(v) and v > 0 for v in d):
            raise DesignError(f"diameters_mm: must be positive numbers, got {list(d)}")
        if not (math.isfinite(self.placement_mm) and self.placement_mm >= 0):
            raise DesignError(f"placement_mm: must be >= 0, got {self.placement_mm}")
        if not (isinstance(self.n_theta, (int, np.integer)) and 16 <= self.n_theta <= 20000):
            raise DesignError(f"n_theta: must be an integer in [16, 20000], got {self.n_theta!r}")
        if not 0 < self.theta_step_meas_deg <= 10:
            raise DesignError("theta_step_meas_deg: must be in (0, 10]")
        if not 0 < self.max_incidence_deg <= 90:
            raise DesignError("max_incidence_deg: must be in (0, 90]")
        if not self.margin_px >= 0:
            raise DesignError("margin_px: must be >= 0")
        if not self.sharpness > 0:
            raise DesignError("sharpness: must be > 0")
        if self.speckle not in SPECKLE_MODELS:
            raise DesignError(f"speckle: must be one of {', '.join(SPECKLE_MODELS)}")
        if not 0 <= self.min_coverage_deg <= 360:
            raise DesignError(f"min_coverage_deg: must be in [0, 360], got {self.min_coverage_deg}")
        if not 0 <= self.min_overlap_deg <= 180:
            raise DesignError(f"min_overlap_deg: must be in [0, 180], got {self.min_overlap_deg}")
        if not 0 <= self.max_multi_reflection_pct <= 100:
            raise DesignError("max_multi_reflection_pct: must be in [0, 100]")
        if not (math.isfinite(self.compensation_diameter_mm) and self.compensation_diameter_mm > 0):
            raise DesignError("compensation_diameter_mm: must be a positive number, got "
                              f"{self.compensation_diameter_mm}")
        if not (isinstance(self.compensation_shots, (int, np.integer))
                and 1 <= self.compensation_shots <= 100):
            raise DesignError("compensation_shots: must be an integer in [1, 100], got "
                              f"{self.compensation_shots!r}")
        if self.bias_model not in BIAS_MODELS:
            raise DesignError(f"bias_model: must be one of {', '.join(BIAS_MODELS)}, got "
                              f"{self.bias_model!r}")
        if self.master and not self.compensate:
            raise DesignError("master: needs the compensation (compensate=True)")
        if self.calibration is not None and not isinstance(
                self.calibration, (CalibrationCovariance, CalibrationPlan)):
            raise DesignError("calibration: must be a CalibrationCovariance, a CalibrationPlan "
                              "or None")

    def cases(self) -> list[tuple[float, float, float]]:
        """``(radius_mm, cx_mm, cy_mm)`` of every case."""
        offs = [(0.0, 0.0)]
        if self.placement_mm > 0:
            p = self.placement_mm
            offs += [(p, 0.0), (-p, 0.0), (0.0, p), (0.0, -p)]
        return [(d / 2.0, cx, cy) for d in self.diameters_mm for cx, cy in offs]

    def model_cases(self) -> list[tuple[float, float, float]]:
        """The cases the model computes: :meth:`cases`, then the compensation's reference
        (the last one) when the compensation is modelled."""
        ref = [(self.compensation_diameter_mm / 2.0, 0.0, 0.0)] if self.compensate else []
        return self.cases() + ref


@dataclasses.dataclass
class Evaluation:
    """One design's values (numpy) and the gradient of the objective.

    Attributes
    ----------
    objective : float
        ``max`` over cases of ``U_um + penalty_um``.
    gradient : (n_free,) float or None
        ``∂objective/∂x`` in the free parameters' units (µm per unit).
    cases : list of (radius_mm, cx_mm, cy_mm)
    U_um, sigma_R_um, point_rms_um, coverage_deg, overlap_direct_left_deg,
    overlap_direct_right_deg, overlap_left_right_deg, multi_reflection_pct, penalty_um,
    speckle_rms_um : (n_cases,) float
        Per case: the radius' expanded uncertainty (k = 2) and σ after the circle fit (all
        shares: the image's noise, the compensation's, the calibration's), the rms
        per-point σ_r, the smooth single-view coverage and overlaps, the smooth share seen
        through both mirrors, the constraint penalty, the rms per-point σ_r of speckle alone.
    sigma_R_noise_um, sigma_R_comp_um, sigma_R_cal_um, sigma_R_bias_um : (n_cases,) float
        The shares of ``sigma_R_um`` (added in quadrature): the measured image's own noise,
        the §4.4 compensation's noise (0 without compensation), the calibration's (0 without
        a covariance), the line-centre bias the corrections leave (``|bias_left_um|``).
    bias_um, bias_left_um : (n_cases,) float
        The line-centre bias of the fitted radius (µm, :mod:`lts360.design.bias`): whole (no
        correction), and what the conditions' master and twin leave of it.
    bias_view_um : dict of (n_cases,) float
        Each single view's mean line-centre bias (µm), whole.
    detail : dict or None
        Per view, per-element arrays (``theta_rad``, ``uv`` (n, 2) px, ``measured`` (soft),
        ``seen``, ``sigma_r_um``, ``sensitivity_mm_per_px``, ``width_px``, ``noise_px`` by term,
        and with a calibration covariance ``cal_dr_mm``: per calibration parameter, in the
        order of its ``names``, the radius change per unit of it) when requested.
    """

    objective: float
    gradient: np.ndarray | None
    cases: list
    U_um: np.ndarray
    sigma_R_um: np.ndarray
    point_rms_um: np.ndarray
    coverage_deg: np.ndarray
    overlap_direct_left_deg: np.ndarray
    overlap_direct_right_deg: np.ndarray
    overlap_left_right_deg: np.ndarray
    multi_reflection_pct: np.ndarray
    penalty_um: np.ndarray
    speckle_rms_um: np.ndarray
    sigma_R_noise_um: np.ndarray | None = None
    sigma_R_comp_um: np.ndarray | None = None
    sigma_R_cal_um: np.ndarray | None = None
    sigma_R_bias_um: np.ndarray | None = None
    bias_um: np.ndarray | None = None
    bias_left_um: np.ndarray | None = None
    bias_view_um: dict | None = None
    detail: dict | None = None

    @property
    def worst_case(self) -> int:
        return int(np.argmax(self.U_um + self.penalty_um))


# ----------------------------------------------------------------------------------- the model
def evaluate(space: DesignSpace, x=None, conditions: Conditions | None = None, *,
             gradient: bool = True, detail: bool = False) -> Evaluation:
    """Evaluate a design: values of every case, and the objective's gradient.

    Parameters
    ----------
    space : DesignSpace
    x : (n_free,) float, optional
        Free parameters in physical units (default: the base rig's values).
    conditions : Conditions, optional
    gradient : bool
        Compute ``∂objective/∂x`` (one reverse-mode pass through the worst case).
    detail : bool
        Also return per-element arrays (:attr:`Evaluation.detail`); not frozen (slower).
    """
    cond = conditions or Conditions()
    values = space.values(x)
    pvec = np.array([values[p.name] for p in PARAMETERS])
    if detail:
        o = DrJitOps()
        res = _run(o, space, cond, o.F(pvec), _grid(o, cond), gradient=False, keep=True)
        det = _detail(o, res.pop("_views"), res.pop("_singles"), res.pop("_theta"),
                      int(cond.n_theta), len(cond.model_cases()), len(cond.cases()))
    else:
        res = _recorded(space, cond, 1, gradient)(pvec)
        det = None
    out = {k: np.asarray(v.numpy(), dtype=float) for k, v in res.items()}
    J = out["J_case"]
    worst = int(np.argmax(J))
    grad = None
    if gradient and not detail:
        order = [p.name for p in PARAMETERS]
        grad = np.array([out["grad"][order.index(nm)] for nm in space.free])
    return Evaluation(objective=float(J[worst]), gradient=grad, cases=cond.cases(),
                      U_um=out["U_um"], sigma_R_um=out["sigma_R_um"],
                      point_rms_um=out["point_rms_um"], coverage_deg=out["coverage_deg"],
                      overlap_direct_left_deg=out["ov_dl"], overlap_direct_right_deg=out["ov_dr"],
                      overlap_left_right_deg=out["ov_lr"], multi_reflection_pct=out["multi"],
                      penalty_um=out["penalty_um"], speckle_rms_um=out["speckle_rms_um"],
                      sigma_R_noise_um=out["sigma_R_noise_um"],
                      sigma_R_comp_um=out["sigma_R_comp_um"],
                      sigma_R_cal_um=out["sigma_R_cal_um"],
                      sigma_R_bias_um=np.abs(out["bias_left_um"]), bias_um=out["bias_um"],
                      bias_left_um=out["bias_left_um"],
                      bias_view_um={k[6:-3]: v for k, v in out.items()
                                    if k.startswith("biasv_")},
                      detail=det)


_FROZEN: dict = {}
#: How many recorded models (space, conditions, batch width, gradient) are kept.
_FROZEN_MAX = 8
#: Designs per batch of :func:`evaluate_batch` (one recorded function; the last batch padded).
BATCH = 128


def _recorded(space: DesignSpace, cond: Conditions, designs: int, gradient: bool):
    """The recorded (``dr.freeze``) model of one space and conditions for ``designs`` designs
    at once: Python traces it once, later calls replay its kernels (the tracing costs ~0.1 s,
    a replay ~ms).  Returns ``call(pvec)`` with ``pvec`` the designs' full parameter vectors
    (design-major)."""
    key = (id(space), cond, designs, gradient)
    hit = _FROZEN.get(key)
    if hit is not None and hit[0] is space:
        return hit[1]
    o = DrJitOps()
    grid = _grid(o, cond, designs)

    @o.dr.freeze
    def run(p, g):
        return _run(o, space, cond, p, g, gradient=gradient, keep=False)

    def call(pvec):
        return run(o.F(np.asarray(pvec, dtype=float)), grid)

    if len(_FROZEN) >= _FROZEN_MAX:
        _FROZEN.pop(next(iter(_FROZEN)))
    _FROZEN[key] = (space, call)
    return call


def _grid(o: DrJitOps, cond: Conditions, designs: int = 1) -> dict:
    """The (design, case, θ) elements as Dr.Jit arrays (made outside the recorded function)."""
    cases = cond.model_cases()
    n_th, n_case, n_user = int(cond.n_theta), len(cases), len(cond.cases())
    blocks = designs * n_case
    th = np.tile(-math.pi + np.arange(n_th) * (2.0 * math.pi / n_th), blocks)
    cs = np.repeat(np.tile(np.asarray(cases, dtype=float), (designs, 1)), n_th, axis=0)
    block = np.repeat(np.arange(blocks), n_th)
    d_of_user = np.repeat(np.arange(designs), n_user)
    user = d_of_user * n_case + np.tile(np.arange(n_user), designs)
    # Each reported case reads its design's reference (the last model case).
    ref = d_of_user * n_case + (n_case - 1)
    # each element's neighbours along θ in its own case (wrapping), for derivatives along θ
    j = np.tile(np.arange(n_th), blocks)
    base_i = np.repeat(np.arange(blocks), n_th) * n_th
    out = dict(theta=o.F(th), ct=o.F(np.cos(th)), st=o.F(np.sin(th)), r=o.F(cs[:, 0]),
               next=o.U(base_i + (j + 1) % n_th), prev=o.U(base_i + (j - 1) % n_th),
               cx=o.F(cs[:, 1]), cy=o.F(cs[:, 2]), ci=o.U(block), di=o.U(block // n_case),
               user=o.U(user), ref=o.U(ref), udi=o.U(d_of_user))
    if isinstance(cond.calibration, CalibrationPlan):
        out.update({f"plan_{k}": v for k, v in
                    cond.calibration.arrays(o.F, o.U, designs).items()})
    o.dr.eval(out)
    return out


def evaluate_batch(space: DesignSpace, X, conditions: Conditions | None = None) -> dict:
    """Values (no gradient) of many designs at once, for maps and grids.

    Parameters
    ----------
    X : (m, n_free) float
        Free parameters in physical units.

    Returns
    -------
    dict of (m, n_cases) float
        ``objective`` is (m,): the worst case's ``U_um + penalty_um``.
    """
    cond = conditions or Conditions()
    X = np.atleast_2d(np.asarray(X, dtype=float))
    base = space.values()
    names = [p.name for p in PARAMETERS]
    full = np.tile([base[nm] for nm in names], (len(X), 1))
    for j, nm in enumerate(space.free):
        full[:, names.index(nm)] = X[:, j]
    call = _recorded(space, cond, BATCH, False)
    n_case = len(cond.cases())  # the reported cases (the outputs are gathered to them)
    parts: dict = {}
    for start in range(0, len(full), BATCH):
        chunk = full[start:start + BATCH]
        pad = np.concatenate([chunk, np.repeat(chunk[-1:], BATCH - len(chunk), axis=0)])
        res = call(pad.reshape(-1))
        for k, v in res.items():
            parts.setdefault(k, []).append(
                np.asarray(v.numpy(), dtype=float).reshape(BATCH, n_case)[:len(chunk)])
    out = {k: np.concatenate(v) for k, v in parts.items()}
    out["objective"] = out["J_case"].max(axis=1)
    return out


def _elements(o: DrJitOps, space: DesignSpace, cond: Conditions, p_all, grid: dict) -> Elements:
    """The parameters at full width, the rig's geometry and the (case, θ) elements."""
    dr, V3 = o.dr, o.V3
    P = {}
    for i, prm in enumerate(PARAMETERS):
        # Full width from the start: the reverse pass then reduces each parameter's gradient
        # once (the gather's adjoint) instead of once per use.
        P[prm.name] = dr.gather(o.F, p_all, grid["di"] * len(PARAMETERS) + i)
    base = space.base
    k = float(cond.sharpness)
    ct, st, r = grid["ct"], grid["st"], grid["r"]
    cxy = (grid["cx"], grid["cy"])
    seqs = mirror_sequences(base.mirrors, 2)
    return Elements(o=o, cond=cond, base=base, P=P, geo=rig_geometry(o, P, space),
                    dist=Distortion(base.camera.distortion), k=k, w_mm=0.5 / k, w_px=1.0 / k,
                    w_cos=0.01 / k, cos_max=math.cos(math.radians(cond.max_incidence_deg)),
                    n_th=int(cond.n_theta), ci=grid["ci"], theta=grid["theta"], ct=ct, st=st,
                    r=r, cxy=cxy, normal=V3(ct, st, 0.0 * ct),
                    X=V3(cxy[0] + r * ct, cxy[1] + r * st, 0.0 * ct), seqs=seqs,
                    names=[view_name(s, base.mirrors) for s in seqs])


def _run(o: DrJitOps, space: DesignSpace, cond: Conditions, pvec, grid: dict, *, gradient: bool,
         keep: bool) -> dict:
    """The model in Dr.Jit: per-case outputs (and ``grad``, ∂J/∂(every parameter)), stage by
    stage: laser, camera views, line widths, exposure and noise, shares, coverage."""
    dr, F = o.dr, o.F
    p_all = F(pvec)
    if gradient:
        dr.enable_grad(p_all)
    e = _elements(o, space, cond, p_all, grid)
    laser = laser_stage(e)
    views = view_stage(e, laser["lit_any"])
    singles = [nm for s, nm in zip(e.seqs, e.names) if len(s) <= 1]
    doubles = [nm for s, nm in zip(e.seqs, e.names) if len(s) == 2]
    line_stage(e, views, singles, laser)
    # One kernel for every per-element quantity; the sums below read them from memory.
    dr.eval(laser["lit_any"], [[views[nm][key] for key in ("measured", "bright", "sig_w",
                                                           "sig_opt", "sens", "arc_px")]
                               for nm in singles],
            [views[nm]["measured"] for nm in doubles])
    noise = noise_stage(e, views, singles, exposure_reference(e, views, singles))

    def at_user(v):
        return dr.gather(F, v, grid["user"])

    def at_ref(v):
        return dr.gather(F, v, grid["ref"])

    var_comp, var_cal = shares_stage(e, space, views, singles, noise, grid, p_all, at_user,
                                     at_ref)
    var_noise = at_user(noise["var_R"])
    cs = noise["cs"]
    bias = bias_stage(e, views, singles, laser, noise, grid, at_user)
    var_bias = (bias["bias_left_um"] * 1e-3) ** 2
    sigma_R_um = dr.sqrt(var_noise + dr.maximum(var_comp, 0.0) + dr.maximum(var_cal, 0.0)
                         + var_bias + 1e-18) * 1e3  # finite slope when 0
    U_um = 2.0 * sigma_R_um
    cover = coverage_stage(e, views, singles, doubles, at_user)
    res = dict(J_case=U_um + cover["penalty_um"], U_um=U_um, sigma_R_um=sigma_R_um,
               point_rms_um=at_user(dr.sqrt(cs["msr2"] / (cs["m"] + 1e-30)) * 1e3),
               speckle_rms_um=at_user(dr.sqrt(cs["msp2"] / (cs["m"] + 1e-30)) * 1e3),
               sigma_R_noise_um=dr.sqrt(var_noise + 1e-18) * 1e3,
               sigma_R_comp_um=dr.sqrt(dr.maximum(var_comp, 0.0) + 1e-18) * 1e3,
               sigma_R_cal_um=dr.sqrt(dr.maximum(var_cal, 0.0) + 1e-18) * 1e3, **bias,
               **cover)
    if gradient:
        res["grad"] = _worst_case_gradient(o, res["J_case"], p_all)
    res = {k: dr.detach(v) for k, v in res.items()}
    dr.eval(res)
    if keep:
        res.update(_views=views, _singles=singles, _theta=e.theta)
    return res


def _worst_case_gradient(o: DrJitOps, J_case, p_all):
    """∂J/∂p of the worst case (ties share): the max is taken on detached values.
    (Reductions by scatter: they are kernel operations, which ``dr.freeze`` records.)"""
    dr, F, U = o.dr, o.F, o.U
    Jd = dr.detach(J_case)
    one = dr.zeros(U, dr.width(J_case))
    jmax = dr.full(F, -1e300, 1)
    dr.scatter_reduce(dr.ReduceOp.Max, jmax, Jd, one)
    w = dr.select(Jd >= dr.gather(F, jmax, one), F(1.0), F(0.0))
    total, wsum = dr.zeros(F, 1), dr.zeros(F, 1)
    dr.scatter_add(total, w * J_case, one)
    dr.scatter_add(wsum, w, one)
    dr.backward(total / wsum)
    return dr.grad(p_all)


def _detail(o: DrJitOps, views, singles, theta, n_th, n_case, n_user) -> dict:
    def arr(v):
        a = np.asarray(o.dr.detach(v).numpy(), dtype=float)
        return a.reshape(n_case, n_th)[:n_user]

    out = {"theta_rad": arr(theta)[0]}
    for name, vw in views.items():
        d = {"uv": np.stack([arr(vw["u"]), arr(vw["v"])], -1), "seen": arr(vw["seen"]),
             "measured": arr(vw["measured"])}
        if "detected" in vw:
            d["detected"] = arr(vw["detected"])
        if name in singles:
            d.update(sigma_r_um=arr(vw["sigma_r_mm"]) * 1e3,
                     sensitivity_mm_per_px=arr(vw["sens"]), width_px=arr(vw["sig_w"]),
                     blur_px=arr(vw["sig_blur"]), sheet_px=arr(vw["sig_geo"]),
                     e_peak=arr(vw["e_peak"]), bias_um=arr(vw["bias_mm"]) * 1e3,
                     bias_um_per_psf2=arr(vw["bias_per_psf2"]) * 1e3,
                     bias_um_per_sheet2=arr(vw["bias_per_sheet2"]) * 1e3,
                     noise_px={k: arr(v) for k, v in vw["noise"].items()})
            if "cal_dr" in vw:
                d["cal_dr_mm"] = [arr(v) for v in vw["cal_dr"]]
        out[name] = d
    return out
