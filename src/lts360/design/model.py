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
  :mod:`lts360.design.calibration`), added in quadrature to the image's own.

Where the model stops (not modelled): the coupling of the calibration's stages (its planes
absorb its K error; the blocks are drawn independently); saturation and the exposure range;
speckle correlated
between pixels (speckle larger than a pixel); the sheet's curvature bias; glossy materials
(the surface is white Lambertian); ambient light.  Every length in mm, angles in radians.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from lts360.design.locking import LOCKING_COEFFS, SIGMA_MAX, SIGMA_MIN
from lts360.design.params import PARAMETERS, DesignError, DesignSpace
from lts360.design.calibration import CalibrationPlan, drjit_ops
from lts360.design.shares import CalibrationCovariance, compensation_shares
from lts360.scenes.coverage import mirror_sequences, view_name

__all__ = ["Conditions", "Evaluation", "evaluate", "evaluate_batch", "pixel_speckle_contrast",
           "plan_covariance_at",
           "SPECKLE_MODELS", "CORRELATION_PX"]

#: ``"pixel"``: the simulator's speckle — a multiplicative pattern of pixel-integrated contrast
#: ``C_px`` (independent between pixels) on a Gaussian line of σ_w px, whose threshold centroid
#: then scatters by ``σ² = C_px² σ_w N2 / D1²`` (``C_px² σ_w / (4 √π)`` without threshold;
#: see :func:`_run`'s noise section and docs/design.md).  ``"dorsch"``: the optical limit of Dorsch,
#: Häusler and Herrmann (Appl. Opt. 33(7) 1994), ``δx = C λ / (2π sin u)`` in the object with
#: ``C = 1`` (fully developed speckle as the lens images it) and ``sin u = A / (2 L)`` the
#: aperture seen along the view's own path ``L``; in the image that is ``λ N / (π p)`` px for
#: every view.
SPECKLE_MODELS = ("pixel", "dorsch")
#: Stripe length (px) over which the errors of neighbouring points are correlated (they share
#: pixels): a point's weight in the circle fit's covariance grows by ``1 + ℓ / arc_px``.
CORRELATION_PX = 1.0
#: Auto-exposure: the stripe's brightness reference is a power mean of this order over the
#: measured points (a smooth stand-in for the simulator's 99.9th percentile).
EXPOSURE_POWER = 16.0
#: Auto-exposure target, as a fraction of the full well.
EXPOSURE_TARGET = 0.8
#: The smooth overlaps are held this much above the required overlap (the smooth and the hard
#: overlap differ by up to a sigmoid width at each end of a window).
OVERLAP_SAFETY_DEG = 2.0
#: Threshold of the peak detector (fraction of full scale) — sets the centroid's window, and
#: a point counts as detected when its peak exceeds it by DETECT_MARGIN (a smooth step of
#: width DETECT_WIDTH / sharpness in that ratio).
THRESHOLD_FRACTION = 0.1
DETECT_MARGIN = 0.25
DETECT_WIDTH = 0.25


def pixel_speckle_contrast(pixel_pitch_um: float, wavelength_nm: float, f_number: float) -> float:
    """Contrast of fully developed speckle integrated by a square pixel (the model's formula).

    The speckle's intensity correlation ``[2 J1(x)/x]²`` is replaced by the Gaussian of the same
    area ``A_c = 4 λ² N² / π``; then per axis
    ``1/M₁ = (2/p²) ∫₀^p (p − Δ) exp(−π Δ²/A_c) dΔ`` in closed form, ``C = 1/M₁`` (``M = M₁²``).
    For 5.3 µm, 660 nm: f/2.8 0.344, f/8 0.726, f/1.4 0.184; the simulator's exact integral
    (:func:`lts360.simulator.speckle.speckle_contrast_theory`, at N(1 + m)): 0.340, 0.726, 0.185.
    """
    lam = wavelength_nm * 1e-3
    a = math.pi / (4.0 * lam * lam * f_number * f_number / math.pi)
    p = pixel_pitch_um
    inv_m1 = (2.0 / (p * p)) * (p * math.sqrt(math.pi) / (2.0 * math.sqrt(a))
                                * math.erf(math.sqrt(a) * p) - (1.0 - math.exp(-a * p * p)) / (2.0 * a))
    return min(inv_m1, 1.0)


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
    calibration : CalibrationCovariance, CalibrationPlan or None
        The calibration's covariance (fixed), or a calibration plan whose covariance the
        model predicts for every design (:class:`lts360.design.calibration.CalibrationPlan`);
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
    sigma_R_noise_um, sigma_R_comp_um, sigma_R_cal_um : (n_cases,) float
        The shares of ``sigma_R_um`` (added in quadrature): the measured image's own noise,
        the §4.4 compensation's noise (0 without compensation), the calibration's (0 without
        a covariance).
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
    detail: dict | None = None

    @property
    def worst_case(self) -> int:
        return int(np.argmax(self.U_um + self.penalty_um))


# ----------------------------------------------------------------------------- Dr.Jit helpers
def _dr():
    import drjit as dr
    from drjit.llvm.ad import Array3f64, Bool, Float64, UInt32

    return dr, Float64, Array3f64, UInt32, Bool


class _Ops:
    """The Dr.Jit types and the few compound operations the model uses."""

    def __init__(self):
        self.dr, self.F, self.V3, self.U, self.B = _dr()

    def sig(self, x):
        """Smooth step of a margin in widths: 0 below −1, 1 above +1, the C¹ cubic
        ``t² (3 − 2t)`` between (a handful of JIT operations, exact 0/1 outside)."""
        t = self.dr.clip(0.5 * x + 0.5, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)

    def relu2(self, x):
        m = self.dr.maximum(x, 0.0)
        return m * m

    def reflect_point(self, p, n, d):
        return p - n * (2.0 * (self.dr.dot(p, n) - d))

    def reflect_dir(self, v, n):
        return v - n * (2.0 * self.dr.dot(v, n))


@dataclasses.dataclass
class _Mirror:
    n: object
    d: object
    c: object
    u: object
    v: object
    half_w: object
    half_h: object


def _geometry(o: _Ops, P: dict, space: DesignSpace):
    """Camera pose, intrinsics, mirrors and laser as Dr.Jit values of the parameters ``P``."""
    dr, V3 = o.dr, o.V3
    base = space.base
    deg = math.pi / 180.0
    a = P["alpha_deg"] * deg
    sa, ca = dr.sin(a), dr.cos(a)
    D = P["camera_distance_mm"]
    pos = V3(0.0, P["camera_target_y_mm"] - D * ca, D * sa)
    # look_at(pos, (0, ty, 0), up=+Z): rows x = (1, 0, 0), y = (0, −sin a, −cos a),
    # z = (0, cos a, −sin a).
    R = ((1.0, 0.0, 0.0), (0.0, -sa, -ca), (0.0, ca, -sa))
    cam = base.camera
    f_px = P["focal_length_mm"] / (cam.pixel_pitch_um * 1e-3)
    cx = (cam.width_px - 1) / 2.0 + float(cam.principal_point_offset_px[0])
    cy = (cam.height_px - 1) / 2.0 + float(cam.principal_point_offset_px[1])
    half = P["beta_deg"] * (deg / 2.0)
    sh, ch = dr.sin(half), dr.cos(half)
    des = base.design
    corner = V3(0.0, P["mirror_corner_distance_mm"], float(des.mirror_center_z_mm))
    mirrors = []
    for sx in (-1.0, 1.0):  # left, right (lts360.scenes.rig._mirrors)
        u = V3(sx * sh, -ch, 0.0 * sh)
        n = V3(-sx * ch, -sh, 0.0 * sh)
        c = corner + u * (P["mirror_width_mm"] / 2.0)
        mirrors.append(_Mirror(n=n, d=dr.dot(n, c), c=c, u=u, v=V3(0.0, 0.0, 1.0),
                               half_w=P["mirror_width_mm"] / 2.0,
                               half_h=float(des.mirror_height_mm) / 2.0))
    laser = V3(0.0, -P["laser_distance_mm"], 0.0 * D)
    return dict(pos=pos, R=R, f_px=f_px, cx=cx, cy=cy, mirrors=mirrors, laser=laser)


def _to_cam(o: _Ops, R, pos, Y):
    """Camera coordinates of world points ``Y`` for the look-at rotation ``R``."""
    q = Y - pos
    return (q.x, R[1][1] * q.y + R[1][2] * q.z, R[2][1] * q.y + R[2][2] * q.z)


def _rot(R, v):
    return (v.x, R[1][1] * v.y + R[1][2] * v.z, R[2][1] * v.y + R[2][2] * v.z)


class _Distortion:
    """Brown distortion of the base camera (constants) and its Jacobian."""

    def __init__(self, dist):
        self.k1, self.k2, self.p1, self.p2, self.k3 = (float(v) for v in dist)
        self.zero = not any((self.k1, self.k2, self.p1, self.p2, self.k3))

    def apply(self, x, y):
        if self.zero:
            return x, y
        k1, k2, p1, p2, k3 = self.k1, self.k2, self.p1, self.p2, self.k3
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)

    def jacobian_apply(self, x, y, dx, dy):
        if self.zero:
            return dx, dy
        k1, k2, p1, p2, k3 = self.k1, self.k2, self.p1, self.p2, self.k3
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        j00 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
        j01 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
        j11 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
        return j00 * dx + j01 * dy, j01 * dx + j11 * dy


def _segment_clear(o: _Ops, a, b, centre_xy, r, mirrors, skip, cyl: bool, w_mm):
    """Soft 'not blocked' of segments a→b by the object cylinder and the other mirrors."""
    dr = o.dr
    s = 1.0
    if cyl:
        ax, ay = a.x - centre_xy[0], a.y - centre_xy[1]
        dx, dy = b.x - a.x, b.y - a.y
        dd = dr.maximum(dx * dx + dy * dy, 1e-18)
        t = dr.clip(-(ax * dx + ay * dy) / dd, 0.0, 1.0)
        qx, qy = ax + t * dx, ay + t * dy
        s = s * o.sig((dr.sqrt(qx * qx + qy * qy + 1e-18) - r) / w_mm)
    for k, m in enumerate(mirrors):
        if k in skip:
            continue
        da, db = dr.dot(a, m.n) - m.d, dr.dot(b, m.n) - m.d
        crosses = o.sig(-da / w_mm) * o.sig(db / w_mm) + o.sig(da / w_mm) * o.sig(-db / w_mm)
        den = da - db
        den = dr.select(dr.abs(den) > 1e-12, den, 1e-12)
        p = a + (b - a) * (da / den)
        q = p - m.c
        qu, qv = dr.dot(q, m.u), dr.dot(q, m.v)
        inside = (o.sig((m.half_w - qu) / w_mm) * o.sig((m.half_w + qu) / w_mm)
                  * o.sig((m.half_h - qv) / w_mm) * o.sig((m.half_h + qv) / w_mm))
        s = s * (1.0 - crosses * inside)
    return s


def _trace(o: _Ops, X, target, seq, mirrors, centre_xy, r, w_mm, w_cos):
    """Soft validity of the path X → mirrors(seq) → target (:func:`coverage.path_valid`).

    Returns ``(soft, leave_dir, arrive_dir, length_mm)``.
    """
    dr = o.dr
    virtual = target
    for k in reversed(seq):
        virtual = o.reflect_point(virtual, mirrors[k].n, mirrors[k].d)
    delta = virtual - X
    length = dr.norm(delta)
    direction = delta / length
    leave = direction
    s = 1.0
    p, first, prev = X, True, None
    for k in seq:
        m = mirrors[k]
        denom = dr.dot(direction, m.n)
        s = s * o.sig(-denom / w_cos)
        den = dr.select(dr.abs(denom) > 1e-12, denom, -1e-12)
        t = (m.d - dr.dot(p, m.n)) / den
        s = s * o.sig(t / w_mm)
        hit = p + direction * t
        q = hit - m.c
        qu, qv = dr.dot(q, m.u), dr.dot(q, m.v)
        s = s * (o.sig((m.half_w - qu) / w_mm) * o.sig((m.half_w + qu) / w_mm)
                 * o.sig((m.half_h - qv) / w_mm) * o.sig((m.half_h + qv) / w_mm))
        skip = {k} if prev is None else {k, prev}
        s = s * _segment_clear(o, p, hit, centre_xy, r, mirrors, skip, not first, w_mm)
        direction = o.reflect_dir(direction, m.n)
        p, first, prev = hit, False, k
    s = s * _segment_clear(o, p, target, centre_xy, r, mirrors,
                           set() if prev is None else {prev}, not first, w_mm)
    return s, leave, direction, length


def _camera_frame_normals(space: DesignSpace) -> dict:
    """The model's plane normals in the base design's camera frame (``{plane: n}``), to
    orient a stored calibration covariance (:meth:`CalibrationCovariance.oriented`)."""
    v = space.values()
    a = math.radians(v["alpha_deg"])
    R = np.array([[1.0, 0.0, 0.0], [0.0, -math.sin(a), -math.cos(a)],
                  [0.0, math.cos(a), -math.sin(a)]])
    half = math.radians(v["beta_deg"]) / 2.0
    out = {"laser": R @ np.array([0.0, 0.0, 1.0])}
    for sx, m in zip((-1.0, 1.0), space.base.mirrors):
        out[m.name] = R @ np.array([-sx * math.cos(half), -math.sin(half), 0.0])
    return out


def _plan_covariance(o: _Ops, space: DesignSpace, plan: CalibrationPlan, grid: dict, p_all):
    """The plan's calibration covariance of every design (per-design arrays)."""
    dr, F = o.dr, o.F
    A = {k[5:]: v for k, v in grid.items() if k.startswith("plan_")}
    designs = dr.width(A["one"])
    ops = drjit_ops()
    npar = len(PARAMETERS)
    cam = space.base.camera
    k1, k2 = float(cam.distortion[0]), float(cam.distortion[1])

    def view(di):
        P = {prm.name: dr.gather(F, p_all, di * npar + i) for i, prm in enumerate(PARAMETERS)}
        geo = _geometry(o, P, space)
        R, pos = geo["R"], geo["pos"]

        def rot(v):
            x, y, z = v
            return [x + 0.0 * pos.x, R[1][1] * y + R[1][2] * z, R[2][1] * y + R[2][2] * z]

        def to_cam(X):
            return rot([X[0] - pos.x, X[1] - pos.y, X[2] - pos.z])

        return {"rot": rot, "to_cam": to_cam, "pos": [pos.x, pos.y, pos.z],
                "intr": (geo["f_px"], geo["f_px"], geo["cx"], geo["cy"], k1, k2),
                "mirrors": [([m.n.x, m.n.y, m.n.z], m.d) for m in geo["mirrors"]]}

    return plan.covariance(ops, A, view, designs)


def plan_covariance_at(space: DesignSpace, plan: CalibrationPlan, x=None) -> np.ndarray:
    """The covariance the model predicts for ``plan`` at one design (numpy, over
    ``plan.names``; for checks and reports)."""
    o = _Ops()
    values = space.values(x)
    p_all = o.F(np.array([values[p.name] for p in PARAMETERS]))
    A = {f"plan_{k}": v for k, v in plan.arrays(o.F, o.U, 1).items()}
    rows = _plan_covariance(o, space, plan, A, p_all)
    K = len(plan.names)
    out = np.zeros((K, K))
    for i in range(K):
        for j in range(K):
            if rows[i][j] is not None:
                out[i, j] = float(np.asarray(o.dr.detach(rows[i][j]).numpy()).reshape(-1)[0])
    return out


def _tangent_world(o: _Ops, R, n_world):
    """The calibration's tangent basis (``tangent_basis`` of the plane's camera-frame normal)
    carried back to the world.  Every normal of the design space has |n_cam.x| < 0.9 (the
    laser's is 0, a mirror's cos(β/2) ≤ 0.87), so the reference axis is always x."""
    dr, V3 = o.dr, o.V3
    n = V3(*_rot(R, n_world))
    e1 = dr.normalize(dr.cross(n, V3(1.0, 0.0, 0.0)))
    e2 = dr.cross(n, e1)

    def back(e):  # Rᵀ e
        return V3(e.x, R[1][1] * e.y + R[2][1] * e.z, R[1][2] * e.y + R[2][2] * e.z)

    return back(e1), back(e2)


def _calibration_dr(o: _Ops, geo: dict, vw: dict, mirrors, mirror_names, names, X, ct, st,
                    dist: "_Distortion"):
    """Per element, the radius change ``δr^k`` (mm per unit) of every calibration parameter.

    The stripe stays at the pixel ``u`` where the true rig images ``X``; the reconstruction,
    with the calibration moved by ``δc_k``, finds the point ``X'`` of its laser plane whose
    (mirrored) projection is ``u``.  For the intrinsics and the mirrors
    ``[∂u/∂r ∂u/∂θ] (δr, δθ) = −δu_k`` (``δu_k`` the change of the projection of the fixed
    ``X``); for the laser plane ``X'`` slides along the (virtual) camera ray to the moved
    plane, ``δr = r̂ · w (δd − δn·X)/(n·w)``.  A plane's ``(a, b, δ)`` turns its camera-frame
    normal and shifts its camera-frame offset: in the world ``δn = Rᵀ e``, ``δd = δ + δn·C``
    (C the camera centre).
    """
    dr, V3 = o.dr, o.V3
    jr, jt = vw["jr"], vw["jt"]
    cross = vw["cross"]
    seq = vw["seq"]
    xn, yn, zs = vw["xn"], vw["yn"], vw["zs"]
    f = geo["f_px"]
    xd, yd = dist.apply(xn, yn)
    r2 = xn * xn + yn * yn
    pos, R = geo["pos"], geo["R"]

    def from_du(du0, du1):
        # jr δr + jt δθ = −δu  →  δr = (δu × jt) / (jt × jr), with a × b = a0 b1 − a1 b0.
        return (du0 * jt[1] - du1 * jt[0]) / cross

    def jac_world(e):  # ∂u/∂Y · e at the view's (virtual) point Y
        dxc, dyc, dzc = _rot(R, e)
        dxn = (dxc - xn * dzc) / zs
        dyn = (dyc - yn * dzc) / zs
        ddx, ddy = dist.jacobian_apply(xn, yn, dxn, dyn)
        return f * ddx, f * ddy

    zero = 0.0 * ct
    cam = {"fx": (xd, zero), "fy": (zero, yd), "cx": (1.0 + zero, zero),
           "cy": (zero, 1.0 + zero), "k1": (f * xn * r2, f * yn * r2),
           "k2": (f * xn * r2 * r2, f * yn * r2 * r2),
           "k3": (f * xn * r2 * r2 * r2, f * yn * r2 * r2 * r2),
           "p1": (f * 2.0 * xn * yn, f * (r2 + 2.0 * yn * yn)),
           "p2": (f * (r2 + 2.0 * xn * xn), f * 2.0 * xn * yn)}
    # The (virtual) camera centre of the view, and the ray direction to X.
    c_v = pos
    for kk in seq:
        c_v = o.reflect_point(c_v, mirrors[kk].n, mirrors[kk].d)
    w = X - c_v
    w_r = w.x * ct + w.y * st
    bases = {}
    out = []
    for full in names:
        plane, _, p = full.partition(".")
        if plane == "camera":
            out.append(from_du(*cam[p]))
            continue
        if plane not in bases:
            n_w = V3(0.0, 0.0, 1.0) if plane == "laser" else mirrors[mirror_names.index(plane)].n
            bases[plane] = _tangent_world(o, R, n_w)
        if p == "delta":
            dn, dd = None, 1.0
        else:
            e = bases[plane][0 if p == "a" else 1]
            dn, dd = e, dr.dot(e, pos)
        if plane == "laser":
            t = (dd - (0.0 if dn is None else dr.dot(dn, X))) / w.z
            out.append(t * w_r)
            continue
        k = mirror_names.index(plane)
        if k not in seq:  # this view does not reflect in that mirror
            out.append(zero)
            continue
        m = mirrors[k]
        s_m = dr.dot(m.n, X) - m.d
        if dn is None:
            dY = m.n * (2.0 * dd)
        else:
            dY = dn * (-2.0 * s_m) - m.n * (2.0 * (dr.dot(dn, X) - dd))
        out.append(from_du(*jac_world(dY)))
    return out


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
        o = _Ops()
        res = _run(o, space, cond, o.F(pvec), _grid(o, cond), gradient=False, keep=True)
        det = _detail(o, res.pop("_views"), res.pop("_singles"), res.pop("_theta"),
                      int(cond.n_theta), len(cond.model_cases()), len(cond.cases()))
    else:
        res = _frozen(space, cond, gradient)(pvec)
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
                      sigma_R_cal_um=out["sigma_R_cal_um"], detail=det)


_FROZEN: dict = {}
#: How many (space, conditions) models stay recorded.
_FROZEN_MAX = 8


def _frozen(space: DesignSpace, cond: Conditions, gradient: bool):
    """The recorded (``dr.freeze``) model of one space and conditions: Python traces it once,
    later calls replay its kernels (the tracing costs ~0.1 s, a replay ~ms)."""
    key = (id(space), cond, gradient)
    hit = _FROZEN.get(key)
    if hit is not None and hit[0] is space:
        return hit[1]
    o = _Ops()
    dr = o.dr

    grid = _grid(o, cond)

    @dr.freeze
    def run(p, g):
        return _run(o, space, cond, p, g, gradient=gradient, keep=False)

    def call(pvec):
        return run(o.F(np.asarray(pvec, dtype=float)), grid)

    if len(_FROZEN) >= _FROZEN_MAX:
        _FROZEN.pop(next(iter(_FROZEN)))
    _FROZEN[key] = (space, call)
    return call


def _grid(o: "_Ops", cond: Conditions, designs: int = 1) -> dict:
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
    out = dict(theta=o.F(th), ct=o.F(np.cos(th)), st=o.F(np.sin(th)), r=o.F(cs[:, 0]),
               cx=o.F(cs[:, 1]), cy=o.F(cs[:, 2]), ci=o.U(block), di=o.U(block // n_case),
               user=o.U(user), ref=o.U(ref), udi=o.U(d_of_user))
    if isinstance(cond.calibration, CalibrationPlan):
        out.update({f"plan_{k}": v for k, v in
                    cond.calibration.arrays(o.F, o.U, designs).items()})
    o.dr.eval(out)
    return out


#: Designs per batch of :func:`evaluate_batch` (one recorded function; the last batch padded).
BATCH = 128


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
    key = (id(space), cond, "batch")
    hit = _FROZEN.get(key)
    if hit is None or hit[0] is not space:
        o = _Ops()
        grid = _grid(o, cond, BATCH)

        @o.dr.freeze
        def run(p, g):
            return _run(o, space, cond, p, g, gradient=False, keep=False)

        def call(pvec):
            return run(o.F(pvec), grid)

        if len(_FROZEN) >= _FROZEN_MAX:
            _FROZEN.pop(next(iter(_FROZEN)))
        _FROZEN[key] = (space, call)
        hit = _FROZEN[key]
    call = hit[1]
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


def _run(o: "_Ops", space: DesignSpace, cond: Conditions, pvec, grid: dict, *, gradient: bool,
         keep: bool) -> dict:
    """The model in Dr.Jit: per-case outputs (and ``grad``, ∂J/∂(every parameter))."""
    dr, F, V3, U = o.dr, o.F, o.V3, o.U
    n_th = int(cond.n_theta)
    n_case = dr.width(grid["ci"]) // n_th  # designs × cases
    p_all = F(pvec)
    if gradient:
        dr.enable_grad(p_all)
    P = {}
    for i, prm in enumerate(PARAMETERS):
        # Full width from the start: the reverse pass then reduces each parameter's gradient
        # once (the gather's adjoint) instead of once per use.
        P[prm.name] = dr.gather(F, p_all, grid["di"] * len(PARAMETERS) + i)
    base = space.base
    cam, las, sensor = base.camera, base.laser, base.sensor
    geo = _geometry(o, P, space)
    mirrors = geo["mirrors"]
    dist = _Distortion(cam.distortion)
    k = float(cond.sharpness)
    w_mm, w_px, w_cos = 0.5 / k, 1.0 / k, 0.01 / k
    cos_max = math.cos(math.radians(cond.max_incidence_deg))

    # --- elements: (case, θ) -------------------------------------------------------------
    step = 2.0 * math.pi / n_th
    ci, theta, ct, st, r = grid["ci"], grid["theta"], grid["ct"], grid["st"], grid["r"]
    cxy = (grid["cx"], grid["cy"])
    normal = V3(ct, st, 0.0 * ct)
    X = V3(cxy[0] + r * ct, cxy[1] + r * st, 0.0 * ct)

    def case_sum(value):
        return dr.block_sum(value + 0.0 * ct, n_th)  # elements are case-major

    # --- the laser: which paths light each point, its irradiance and the sheet's σ ----------
    seqs = mirror_sequences(base.mirrors, 2)
    names = [view_name(s, base.mirrors) for s in seqs]
    rho_m = float(base.design.mirror_reflectance)
    w0_mm = P["waist_um"] * 1e-3
    lam_mm = las.wavelength_nm * 1e-6
    z_r = math.pi / (lam_mm * las.m_squared) * w0_mm * w0_mm
    cos_half_fan = dr.cos(P["fan_angle_deg"] * (math.pi / 360.0))
    unlit = 1.0
    E_sum, Esig_sum = 0.0, 0.0
    for seq in seqs:
        s_lit, leave, arrive, L = _trace(o, X, geo["laser"], seq, mirrors, cxy, r, w_mm, w_cos)
        cos_i = dr.dot(leave, normal)
        s_lit = s_lit * o.sig((cos_i - cos_max) / w_cos)
        s_lit = s_lit * o.sig((-arrive.y - cos_half_fan) / w_cos)  # emitted · (0, 1, 0)
        unlit = unlit * (1.0 - s_lit)
        zz = (L - P["laser_distance_mm"]) / z_r
        sig_sheet = 0.5 * w0_mm * dr.sqrt(1.0 + zz * zz)
        E = s_lit * (rho_m ** len(seq)) * dr.maximum(cos_i, 0.0) / (L * sig_sheet)
        E_sum = E_sum + E
        Esig_sum = Esig_sum + E * sig_sheet
    lit_any = 1.0 - unlit
    sig_sheet_eff = Esig_sum / (E_sum + 1e-30)

    # --- camera views ------------------------------------------------------------------------
    f_mm, N = P["focal_length_mm"], P["f_number"]
    s_f = P["focus_distance_mm"]
    aperture = f_mm / N
    pitch_mm = cam.pixel_pitch_um * 1e-3
    W, H = cam.width_px, cam.height_px
    margin = cond.margin_px
    views = {}
    for seq, name in zip(seqs, names):
        s_seen, leave, _, _ = _trace(o, X, geo["pos"], seq, mirrors, cxy, r, w_mm, w_cos)
        s_seen = s_seen * o.sig((dr.dot(leave, normal) - cos_max) / w_cos)
        Y = X
        for kk in seq:
            Y = o.reflect_point(Y, mirrors[kk].n, mirrors[kk].d)
        xc, yc, zc = _to_cam(o, geo["R"], geo["pos"], Y)
        s_seen = s_seen * o.sig(zc / w_mm)
        zs = dr.select(zc > 1e-9, zc, 1e-9)
        xn, yn = xc / zs, yc / zs
        xd, yd = dist.apply(xn, yn)
        u = geo["f_px"] * xd + geo["cx"]
        v = geo["f_px"] * yd + geo["cy"]
        s_seen = s_seen * (o.sig((u + 0.5 - margin) / w_px) * o.sig((W - 0.5 - margin - u) / w_px)
                           * o.sig((v + 0.5 - margin) / w_px)
                           * o.sig((H - 0.5 - margin - v) / w_px))
        views[name] = dict(seq=seq, seen=s_seen, measured=s_seen * lit_any, u=u, v=v, zc=zc,
                           xn=xn, yn=yn, zs=zs)

    singles = [nm for s, nm in zip(seqs, names) if len(s) <= 1]
    doubles = [nm for s, nm in zip(seqs, names) if len(s) == 2]

    # --- per view: Jacobians, line width, brightness -----------------------------------------
    lam_um = las.wavelength_nm * 1e-3
    for name in singles:
        vw = views[name]
        seq = vw["seq"]

        def jac(e, seq=seq, vw=vw):
            for kk in seq:
                e = o.reflect_dir(e, mirrors[kk].n)
            dxc, dyc, dzc = _rot(geo["R"], e)
            dxn = (dxc - vw["xn"] * dzc) / vw["zs"]
            dyn = (dyc - vw["yn"] * dzc) / vw["zs"]
            ddx, ddy = dist.jacobian_apply(vw["xn"], vw["yn"], dxn, dyn)
            return geo["f_px"] * ddx, geo["f_px"] * ddy

        jr = jac(V3(ct, st, 0.0 * ct))
        jt = jac(V3(-r * st, r * ct, 0.0 * ct))
        jz = jac(V3(0.0 * ct, 0.0 * ct, 1.0 + 0.0 * ct))
        jt_norm = dr.sqrt(jt[0] * jt[0] + jt[1] * jt[1] + 1e-24)
        cross = jt[0] * jr[1] - jt[1] * jr[0]
        vw.update(jr=jr, jt=jt, cross=dr.select(dr.abs(cross) > 1e-12, cross, 1e-12))
        sens = jt_norm / dr.sqrt(cross * cross + 1e-24)  # mm per px across the line
        nz = (-jt[1] * jz[0] + jt[0] * jz[1]) / jt_norm
        sig_geo = sig_sheet_eff * dr.sqrt(nz * nz + 1e-24)
        dz = vw["zs"] - s_f
        blur_mm = aperture * f_mm * dr.sqrt(dz * dz + 1e-12) / (vw["zs"] * (s_f - f_mm))
        sig_blur = blur_mm / (4.0 * pitch_mm)
        sig_diff = 0.42 * lam_um * 1e-3 * N / pitch_mm
        sig_opt = dr.sqrt(sig_geo * sig_geo + sig_blur * sig_blur + sig_diff * sig_diff)
        sig_w = dr.sqrt(sig_opt * sig_opt + 1.0 / 12.0)
        vw.update(sens=sens, sig_geo=sig_geo, sig_blur=sig_blur, sig_opt=sig_opt, sig_w=sig_w,
                  arc_px=jt_norm * math.radians(cond.theta_step_meas_deg),
                  bright=E_sum * (rho_m ** len(seq)) * sig_geo / sig_w)

    # One kernel for every per-element quantity; the sums below read them from memory.
    dr.eval(lit_any, [[views[nm][key] for key in ("measured", "bright", "sig_w", "sig_opt",
                                                   "sens", "arc_px")] for nm in singles],
            [views[nm]["measured"] for nm in doubles])

    # --- auto-exposure (per case: one image each) -------------------------------------------
    q = EXPOSURE_POWER
    num, den = 0.0, 0.0
    for name in singles:
        vw = views[name]
        num = num + case_sum(vw["measured"] * dr.exp(q * dr.log(vw["bright"] + 1e-300)))
        den = den + case_sum(vw["measured"])
    b_ref = dr.gather(F, dr.exp(dr.log(num / (den + 1e-30) + 1e-300) / q), ci)

    # --- line-position noise (px across the line) and σ_r -----------------------------------
    fw = float(sensor.full_well_e)
    K = float(sensor.system_gain)
    read2 = float(sensor.dark_noise_e) ** 2 + 1.0 / (12.0 * K * K)
    # The threshold in electrons (10 % of full scale, less the black level).
    thr_e = (THRESHOLD_FRACTION * (2 ** int(sensor.bit_depth) - 1)
             - float(sensor.dark_offset_dn)) / K
    a_c = 4.0 * lam_um * lam_um * N * N / math.pi  # speckle correlation area (µm²)
    a_g = math.pi / a_c
    p_um = cam.pixel_pitch_um
    sa = dr.sqrt(a_g)
    inv_m1 = (2.0 / (p_um * p_um)) * (p_um * math.sqrt(math.pi) / (2.0 * sa) * dr.erf(sa * p_um)
                                      - (1.0 - dr.exp(-a_g * p_um * p_um)) / (2.0 * a_g))
    c_px2 = dr.minimum(inv_m1 * inv_m1, 1.0)  # pixel-integrated speckle contrast²
    c0, c1, c2, c3 = LOCKING_COEFFS
    sums = {key: 0.0 for key in ("a", "b", "c", "d", "e", "f", "Sa", "Sb", "Sc", "Sd", "Se",
                                 "Sf", "m", "msr2", "msp2")}
    nu = math.degrees(step) / cond.theta_step_meas_deg  # measured points per model sample
    mir_names = [m_.name for m_ in base.mirrors]
    cal = cond.calibration
    cal_names = list(cal.names) if cal is not None else []
    view_A, view_B, view_dr = {}, {}, {}
    for name in singles:
        vw = views[name]
        sw = vw["sig_w"]
        # At least one electron: an unlit point then has a large but finite σ (and weight 0).
        e_peak = dr.maximum(EXPOSURE_TARGET * fw * vw["bright"] / b_ref, 1.0)
        # Centroid of I − t over the run above the threshold t = τ·peak, in units of σ_w:
        # window ±a, a = √(2 ln 1/τ); D1 = ∫(g − τ), N1 = ∫x² g, N2 = ∫x² g² (g = e^{−x²/2}).
        tau = dr.clip(thr_e / e_peak, 1e-3, 0.95)
        a = dr.sqrt(2.0 * dr.log(1.0 / tau))
        erf_a2 = dr.erf(a * (1.0 / math.sqrt(2.0)))
        ea2 = dr.exp(-0.5 * a * a)
        d1 = math.sqrt(2.0 * math.pi) * erf_a2 - 2.0 * a * tau
        n1 = math.sqrt(2.0 * math.pi) * erf_a2 - 2.0 * a * ea2
        n2 = 0.5 * math.sqrt(math.pi) * dr.erf(a) - a * ea2 * ea2
        n_shot2 = sw * n1 / (e_peak * d1 * d1)
        n_read2 = read2 * sw * (2.0 * a * a * a / 3.0) / (e_peak * e_peak * d1 * d1)
        if cond.speckle == "pixel":
            n_sp2 = c_px2 * sw * n2 / (d1 * d1)
        else:
            n_sp = lam_um * N / (math.pi * p_um)
            n_sp2 = n_sp * n_sp + 0.0 * sw
        so = dr.clip(vw["sig_opt"], SIGMA_MIN, SIGMA_MAX)
        n_lock = dr.exp(c0 + so * (c1 + so * (c2 + so * c3)))
        n_lock2 = n_lock * n_lock
        noise2 = n_sp2 + n_shot2 + n_read2 + n_lock2
        sr_mm = dr.sqrt(noise2) * vw["sens"]
        vw.update(noise=dict(speckle=dr.sqrt(n_sp2), shot=dr.sqrt(n_shot2),
                             read=dr.sqrt(n_read2), locking=n_lock), sigma_r_mm=sr_mm,
                  e_peak=e_peak)
        # The peak detector's threshold: a line whose peak falls under it (dim, or blurred
        # by defocus) is lost.
        ratio = e_peak / thr_e
        vw["detected"] = vw["measured"] * o.sig((ratio - 1.0 - DETECT_MARGIN) / (DETECT_WIDTH / k))
        m = vw["detected"] * nu
        corr = 1.0 + CORRELATION_PX / (vw["arc_px"] + 1e-12)
        w2 = m * corr * sr_mm * sr_mm
        basis6 = (1.0, ct, st, ct * ct, ct * st, st * st)
        view_A[name] = [m * b for b in basis6]
        view_B[name] = [w2 * b for b in basis6]
        if cal_names:
            vw["cal_dr"] = _calibration_dr(o, geo, vw, mirrors, mir_names, cal_names, X, ct, st,
                                           dist)
            view_dr[name] = [[m * dk, m * dk * ct, m * dk * st] for dk in vw["cal_dr"]]
        for key, val in (("a", 1.0), ("b", ct), ("c", st), ("d", ct * ct), ("e", ct * st),
                         ("f", st * st)):
            sums[key] = sums[key] + m * val
            sums["S" + key] = sums["S" + key] + w2 * val
        sums["m"] = sums["m"] + m
        sums["msr2"] = sums["msr2"] + m * sr_mm * sr_mm
        sums["msp2"] = sums["msp2"] + m * n_sp2 * vw["sens"] * vw["sens"]
    cs = {key: case_sum(val + 0.0 * ct) for key, val in sums.items()}
    a_, b_, c_, d_, e_, f_ = (cs[key] for key in "abcdef")
    det = a_ * (d_ * f_ - e_ * e_) - b_ * (b_ * f_ - c_ * e_) + c_ * (b_ * e_ - c_ * d_)
    det = dr.maximum(det, 1e-30)
    g0, g1, g2 = (d_ * f_ - e_ * e_) / det, (c_ * e_ - b_ * f_) / det, (b_ * e_ - c_ * d_) / det
    var_R = (g0 * (cs["Sa"] * g0 + cs["Sb"] * g1 + cs["Sc"] * g2)
             + g1 * (cs["Sb"] * g0 + cs["Sd"] * g1 + cs["Se"] * g2)
             + g2 * (cs["Sc"] * g0 + cs["Se"] * g1 + cs["Sf"] * g2))
    var_noise = dr.maximum(var_R, 0.0)
    # --- the §4.4 compensation's noise and the calibration's share --------------------------
    user, refi = grid["user"], grid["ref"]

    def at_user(v):
        return dr.gather(F, v, user)

    def at_ref(v):
        return dr.gather(F, v, refi)

    var_comp, var_cal = 0.0 * at_user(var_noise), 0.0 * at_user(var_noise)
    if cond.compensate or cal_names:
        A_sums = {nm: [case_sum(v) for v in view_A[nm]] for nm in singles}
        B_sums = {nm: [case_sum(v) for v in view_B[nm]] for nm in singles}
        dr_sums = {nm: [[case_sum(v) for v in trio] for trio in view_dr[nm]]
                   for nm in view_dr}
        if isinstance(cal, CalibrationPlan):
            cov = [[None if c is None else dr.gather(F, c, grid["udi"]) for c in row]
                   for row in _plan_covariance(o, space, cal, grid, p_all)]
        else:
            cov = cal.oriented(_camera_frame_normals(space)) if cal is not None else None
        var_comp, var_cal = compensation_shares(
            {nm: [at_user(v) for v in A_sums[nm]] for nm in singles},
            {nm: [at_ref(v) for v in A_sums[nm]] for nm in singles},
            {nm: [at_ref(v) for v in B_sums[nm]] for nm in singles},
            {nm: [[at_user(v) for v in trio] for trio in dr_sums[nm]] for nm in dr_sums},
            {nm: [[at_ref(v) for v in trio] for trio in dr_sums[nm]] for nm in dr_sums},
            cov, [nm for nm in singles if nm != "direct"], dr.sqrt,
            shots=int(cond.compensation_shots), compensate=bool(cond.compensate))
    var_noise = at_user(var_noise)
    sigma_R_noise_um = dr.sqrt(var_noise + 1e-18) * 1e3
    sigma_R_comp_um = dr.sqrt(dr.maximum(var_comp, 0.0) + 1e-18) * 1e3
    sigma_R_cal_um = dr.sqrt(dr.maximum(var_cal, 0.0) + 1e-18) * 1e3
    sigma_R_um = dr.sqrt(var_noise + dr.maximum(var_comp, 0.0) + dr.maximum(var_cal, 0.0)
                         + 1e-18) * 1e3  # finite slope when 0
    U_um = 2.0 * sigma_R_um
    point_rms_um = at_user(dr.sqrt(cs["msr2"] / (cs["m"] + 1e-30)) * 1e3)
    speckle_rms_um = at_user(dr.sqrt(cs["msp2"] / (cs["m"] + 1e-30)) * 1e3)

    # --- coverage, overlaps, multiple reflections, penalties --------------------------------
    step_deg = math.degrees(step)
    none_single = 1.0
    for name in singles:
        none_single = none_single * (1.0 - views[name]["detected"])
    union1 = 1.0 - none_single
    none_double = 1.0
    for name in doubles:
        none_double = none_double * (1.0 - views[name]["measured"])
    cov = case_sum(union1 * step_deg)
    mir = [m.name for m in base.mirrors]
    md, ml, mr = (views[nm]["detected"] for nm in ("direct", mir[0], mir[1]))
    ov_dl, ov_dr, ov_lr = (case_sum(a * b * step_deg) for a, b in ((md, ml), (md, mr), (ml, mr)))
    multi = case_sum(union1 * (1.0 - none_double) * (100.0 / n_th))
    wpen = cond.penalty_um_per_deg2
    min_ov = cond.min_overlap_deg + OVERLAP_SAFETY_DEG if cond.min_overlap_deg > 0 else 0.0
    pen = wpen * (o.relu2(cond.min_coverage_deg - cov) + o.relu2(min_ov - ov_dl)
                  + o.relu2(min_ov - ov_dr) + o.relu2(min_ov - ov_lr)
                  + o.relu2(multi - cond.max_multi_reflection_pct))
    # The rig's own validity: mirrors clear the largest object, camera and laser in front.
    r_max = float(base.design.max_object_radius_mm)
    clear = P["mirror_corner_distance_mm"] * dr.sin(P["beta_deg"] * (math.pi / 360.0)) - r_max
    rig_pen = o.relu2(1.0 - clear) + o.relu2(r_max + 1.0 - P["laser_distance_mm"])
    for m in mirrors:
        rig_pen = rig_pen + o.relu2(1.0 - (dr.dot(m.n, geo["pos"]) - m.d))
        rig_pen = rig_pen + o.relu2(1.0 - (dr.dot(m.n, geo["laser"]) - m.d))
    rig_pen = rig_pen + o.relu2(1.0 - (s_f - f_mm))
    rig_pen = case_sum(rig_pen * (1.0 / n_th))  # the same in every element: per case
    pen = at_user(pen + 1e3 * rig_pen)
    J_case = U_um + pen
    res = dict(J_case=J_case, U_um=U_um, sigma_R_um=sigma_R_um, point_rms_um=point_rms_um,
               coverage_deg=at_user(cov), ov_dl=at_user(ov_dl), ov_dr=at_user(ov_dr),
               ov_lr=at_user(ov_lr), multi=at_user(multi), penalty_um=pen,
               speckle_rms_um=speckle_rms_um, sigma_R_noise_um=sigma_R_noise_um,
               sigma_R_comp_um=sigma_R_comp_um, sigma_R_cal_um=sigma_R_cal_um)
    if gradient:
        # The worst case (ties share): the max is taken on detached values.
        # (Reductions by scatter: they are kernel operations, which dr.freeze records.)
        Jd = dr.detach(J_case)
        one = dr.zeros(U, dr.width(J_case))
        jmax = dr.full(F, -1e300, 1)
        dr.scatter_reduce(dr.ReduceOp.Max, jmax, Jd, one)
        w = dr.select(Jd >= dr.gather(F, jmax, one), F(1.0), F(0.0))
        total, wsum = dr.zeros(F, 1), dr.zeros(F, 1)
        dr.scatter_add(total, w * J_case, one)
        dr.scatter_add(wsum, w, one)
        dr.backward(total / wsum)
        res["grad"] = dr.grad(p_all)
    res = {k: dr.detach(v) for k, v in res.items()}
    dr.eval(res)
    if keep:
        res.update(_views=views, _singles=singles, _theta=theta)
    return res


def _detail(o: _Ops, views, singles, theta, n_th, n_case, n_user) -> dict:
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
                     e_peak=arr(vw["e_peak"]),
                     noise_px={k: arr(v) for k, v in vw["noise"].items()})
            if "cal_dr" in vw:
                d["cal_dr_mm"] = [arr(v) for v in vw["cal_dr"]]
        out[name] = d
    return out
