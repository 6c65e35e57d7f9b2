"""Model-based line-centre bias correction: measure the twin of the section with the same
plan, and subtract what the chain does to a profile whose radii are known exactly.

For each section: the measured points give a closed profile (:mod:`lts360.twin.profile`); its
prism is rendered noise-free through the calibrated rig with the rig file's optics
(:mod:`lts360.twin.rig`: the camera sees it through the calibrated mirrors, the laser lights
it through them turned perpendicular to the calibrated sheet), only on the pixels the plan reads; the twin image is measured by the
very function (same grid, windows, detector, compensation, rejection) that measured the real
image.  Per view and θ the bias is ``b = r_twin_measured − r_twin_exact`` (the exact radius of
the prism along the same ray), smoothed along θ over ``smooth_deg`` (the twin's render noise),
and the real radii become ``r − b``.  A valid point farther than ``smooth_deg / 2`` from any
twin estimate of its view keeps its radius and is counted as uncorrected.

What the correction cannot know is what the twin does not model: the real surface's micro-
structure and material beyond the chosen BSDF, and the geometry between the sections (the prism
is straight).  Two uncertainties of the correction are estimated and recorded per view:
``u_render_um``, what the twin's render noise leaves in it, and ``u_inputs_um``, how much it
moves when the rig file's optics are off by their standard uncertainty (:data:`INPUT_U`: the
focus distance, the f-number, the sheet's waist), each found by rendering the twin again with
that input moved (the same samples, so the difference is the input's) on the first section
corrected and used for every section.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from lts360.recon.model import Calibration
from lts360.scenes.materials import get_material
from lts360.scenes.rig import Rig
from lts360.twin.corners import sharpen_corners
from lts360.twin.profile import axial_form, loft_mesh, ray_radii, section_profile
from lts360.twin.rig import laser_side_mirrors, twin_rig

__all__ = ["TwinCorrector", "TwinLog", "twin_corrected", "twin_corrected_raw", "DEFAULT_TWIN_SPP", "DEFAULT_SMOOTH_DEG", "INPUT_U",
           "DEFAULT_AXIAL_REACH_MM", "MAX_AXIAL_REACH_MM",
           "perturbed_design"]

DEFAULT_TWIN_SPP = 64
DEFAULT_SMOOTH_DEG = 3.0
#: Smoothing of the bias along θ about a sharpened corner, where it changes by tens of µm per
#: degree (the 3° default would spread a corner's correction over its faces).
CORNER_SMOOTH_DEG = 0.5
#: Sections within this axial distance shape the twin along the axis (the sheet lights about
#: ±0.6 mm of it; a pipe's 5 mm waviness is a quadratic within a few % over ±1 mm).
DEFAULT_AXIAL_REACH_MM = 1.0
#: The farthest reach along the axis: beyond it the quadratic form no longer holds a waviness.
MAX_AXIAL_REACH_MM = 10.0
#: Passes of a scan's correction when the twin is shaped along the axis: the second reads the
#: form from the corrected profiles (measured, the alu pipe's 0.1 mm waviness: the sections'
#: diameter errors −4.5…−7.7 µm after one pass, −2.1…+1.2 µm after two; a third adds nothing).
DEFAULT_AXIAL_PASSES = 2
#: Standard uncertainties of the rig file's inputs the twin depends on (type B, a design's
#: tolerances): focus distance (mm), f-number and the sheet's waist (relative).
INPUT_U = {"focus_distance_mm": 2.0, "f_number_rel": 0.05, "waist_rel": 0.10}
#: The twin's default render seed: not a frame's usual seed (a twin sharing the real render's
#: sample pattern would cancel that render's sampling noise, which no real image has).
TWIN_SEED = 0x7717


@dataclass
class TwinLog:
    """What the correction did, one entry per section: per view the mean bias removed (µm),
    its spread along θ, the corrected and uncorrected point counts, ``u_render_um`` and the
    correction itself (``theta_rad``, ``bias_mm``: per corrected point)."""

    sections: list = field(default_factory=list)
    render_s: float = 0.0
    measure_s: float = 0.0
    #: Per view: the correction's change for each input moved by its u (µm), and their RSS.
    inputs: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """Per view over all sections: mean bias (µm), points corrected and uncorrected."""
        out: dict = {}
        for sec in self.sections:
            for name, d in sec["views"].items():
                o = out.setdefault(name, {"bias_sum_um": 0.0, "n_corrected": 0,
                                          "n_uncorrected": 0, "u_render_um": 0.0,
                                          "u_inputs_um": self.inputs.get(name, {}).get(
                                              "u_um", float("nan"))})
                o["bias_sum_um"] += d["mean_bias_um"] * d["n_corrected"]
                o["n_corrected"] += d["n_corrected"]
                o["n_uncorrected"] += d["n_uncorrected"]
                o["u_render_um"] = max(o["u_render_um"], d["u_render_um"])
        for o in out.values():
            o["mean_bias_um"] = o.pop("bias_sum_um") / max(o["n_corrected"], 1)
        return out

    def describe(self) -> str:
        s = self.summary()
        return "twin bias correction: " + ", ".join(
            f"{k} {v['mean_bias_um']:+.2f} µm ({v['n_corrected']} pts"
            + (f", {v['n_uncorrected']} uncorrected" if v["n_uncorrected"] else "")
            + (f", u(inputs) {v['u_inputs_um']:.2f} µm" if np.isfinite(v["u_inputs_um"]) else "")
            + ")" for k, v in s.items()) + (
            f"; {n_ax} of {len(self.sections)} section(s) shaped along the axis by their "
            f"neighbours" if (n_ax := sum(1 for e in self.sections if e.get("axial"))) else "") \
            + self._describe_corners() + f"; render {self.render_s:.1f} s"

    def _describe_corners(self) -> str:
        rows = [c for e in self.sections for c in e.get("corners", [])]
        if not any("corners" in e for e in self.sections):
            return ""
        kept = sum(1 for c in rows if c["sharpened"])
        return f"; corners: {len(rows)} found, {kept} sharpened in the twin"


def perturbed_design(design: Rig, key: str, u: float) -> Rig:
    """``design`` with one input of :data:`INPUT_U` moved by ``u``."""
    cam, las = design.camera, design.laser
    if key == "focus_distance_mm":
        return dataclasses.replace(design, camera=dataclasses.replace(
            cam, focus_distance_mm=cam.focus_distance_mm + u))
    if key == "f_number_rel":
        return dataclasses.replace(design, camera=dataclasses.replace(
            cam, f_number=cam.f_number * (1 + u)))
    if key == "waist_rel":
        w = las.waist_um * (1 + u)
        # the beam quality is kept: z_R scales with w0²
        return dataclasses.replace(design, laser=dataclasses.replace(
            las, waist_um=w, rayleigh_range_mm=las.rayleigh_range_mm * (1 + u) ** 2))
    raise ValueError(f"unknown twin input {key!r}; known: {', '.join(INPUT_U)}")


def _compensated(verts_mm: np.ndarray, cal, name: str, compensate: bool) -> np.ndarray:
    """The profile ``verts_mm`` (n, 2) as a compensated measurement of view ``name`` reads
    it: radii ``scale·ρ + radial offset`` along the rays from the origin, then the view's
    translation (:func:`lts360.recon.triangulation.inverse.compensation_of`)."""
    from lts360.recon.triangulation.inverse import compensation_of

    kw = compensation_of(cal, name, compensate)
    if not kw:
        return verts_mm
    rho = np.hypot(*verts_mm.T)
    out = verts_mm * ((kw["scale"] * rho + kw["radial_offset_mm"]) / rho)[:, None]
    return out + kw.get("offset_mm", np.zeros(2))


def _nan_smooth(values: np.ndarray, size: int, wrap: bool) -> tuple[np.ndarray, np.ndarray]:
    """Moving mean of the finite values over ``size`` samples; (mean, count) per sample."""
    from scipy.ndimage import uniform_filter1d

    ok = np.isfinite(values)
    mode = "wrap" if wrap else "constant"
    s = uniform_filter1d(np.where(ok, values, 0.0), size, mode=mode)
    n = uniform_filter1d(ok.astype(float), size, mode=mode)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s / n
    count = np.rint(n * size)
    return np.where(count > 0, mean, np.nan), count


def _stencil(neighbours: list) -> list:
    """The three-point stencil about a section: the nearest neighbour on each side, or the two
    nearest on the one side there is (a quadratic through more, farther sections bends less
    than the surface: a 5 mm waviness's curvature read 20 % low over ±1 mm, 3 % over ±0.5)."""
    below = sorted((n for n in neighbours if n[0] < 0), key=lambda n: -n[0])
    above = sorted((n for n in neighbours if n[0] > 0), key=lambda n: n[0])
    if below and above:
        return [below[0], above[0]]
    return (below or above)[:2]


@dataclass
class TwinCorrector:
    """A ``correct`` hook for :func:`lts360.recon.triangulation.measure.measure_sections_following`
    (and :func:`~lts360.recon.triangulation.measure.measure_sections`).

    Attributes
    ----------
    cal : Calibration
        The calibration the real image is measured with (the twin's geometry).
    design : Rig
        The rig file: optics, laser, sensor of the twin.
    material : str
        The twin's surface (:mod:`lts360.scenes.materials`).
    spp, seed : int
        The twin's render (noise-free; ``spp`` ≥ 64 for µm work); section ``k`` of a scan
        renders with ``seed + k``.
    smooth_deg : float
        Smoothing of the bias along θ (and its reach across twin gaps).
    half_length_mm : float
        Half-length of the twin prism along the axis.
    input_u : dict or None
        The inputs' standard uncertainties (:data:`INPUT_U`); ``None``: not evaluated.
    axial_passes : int
        Passes over a scan when the twin is shaped along the axis (:meth:`passes`).
    corners : bool
        Restore the measured profile's sharp corners in the twin
        (:func:`lts360.twin.corners.sharpen_corners`): the twin is rendered with and without
        them, and each corner keeps the one whose twin measures more like the real image
        (rms over the corner's zone, ±(zone + 1°)); about a kept corner the bias is smoothed
        over :data:`CORNER_SMOOTH_DEG` only.  One more small render per section with corners.
    axial_reach_mm : float
        In a scan, the sections within this axial distance of a section give the twin its form
        along the axis (:func:`lts360.twin.profile.axial_form`: slope and curvature per φ), so
        that a surface curved along the axis (a pipe's waviness) is rendered so; 0 (or a
        single section) keeps the straight prism.  The measuring loop must then call
        :meth:`observe` for every section before correcting any.
    """

    cal: Calibration
    design: Rig
    material: str = "ground-steel"
    spp: int = DEFAULT_TWIN_SPP
    seed: int = TWIN_SEED
    smooth_deg: float = DEFAULT_SMOOTH_DEG
    half_length_mm: float = 30.0
    input_u: dict | None = field(default_factory=lambda: dict(INPUT_U))
    axial_reach_mm: float = DEFAULT_AXIAL_REACH_MM
    axial_passes: int = DEFAULT_AXIAL_PASSES
    corners: bool = False
    log: TwinLog = field(default_factory=TwinLog)

    def __post_init__(self) -> None:
        get_material(self.material)  # fails with the list of materials
        if isinstance(self.spp, bool) or not isinstance(self.spp, (int, np.integer)) \
                or self.spp < 1:
            raise ValueError(f"twin spp must be an integer >= 1, got {self.spp!r}")
        if not 0 < self.smooth_deg <= 30:
            raise ValueError(f"twin smooth_deg must be in (0, 30], got {self.smooth_deg}")
        if not 0 <= self.axial_reach_mm <= MAX_AXIAL_REACH_MM:
            raise ValueError(f"twin axial_reach_mm must be in [0, {MAX_AXIAL_REACH_MM:g}], got "
                             f"{self.axial_reach_mm}")
        if not 1 <= int(self.axial_passes) <= 5:
            raise ValueError(f"twin axial_passes must be in [1, 5], got {self.axial_passes}")
        self._observed: list = []  # (z_mm, profile in the base frame or None, origin)
        self._rigs = {id(self.cal): (self.cal, twin_rig(self.cal, self.design))}

    @property
    def rig(self) -> Rig:
        """The twin's rig for ``cal``."""
        return self._rigs[id(self.cal)][1]

    def rig_for(self, cal: Calibration) -> Rig:
        """The twin's rig for a plan's calibration (``cal`` itself, or ``cal`` with its origin
        moved to a section's centre)."""
        if id(cal) not in self._rigs:
            self._rigs[id(cal)] = (cal, twin_rig(cal, self.design))
        return self._rigs[id(cal)][1]

    # -- the twin image ----------------------------------------------------------------------
    def render(self, surface, pixels_xy: np.ndarray, *, seed: int, exposure_fraction: float,
               rig: Rig | None = None) -> np.ndarray:
        """The twin's noise-free digital image of ``surface`` (a closed mesh, or a profile
        extruded straight; only ``pixels_xy`` rendered; ``rig`` defaults to :attr:`rig`)."""
        from lts360.simulator.frame import sensor_image
        from lts360.simulator.materials import material_to_bsdf
        from lts360.simulator.render import ensure_variant, render_radiance_pixels
        from lts360.simulator.scene import SceneSpec

        ensure_variant()
        rig = self.rig if rig is None else rig
        mesh = (surface if hasattr(surface, "faces")
                else loft_mesh(surface, half_length_mm=self.half_length_mm))
        spec = SceneSpec(rig, (("object", mesh,
                                     material_to_bsdf(get_material(self.material))),),
                         laser_mirrors=laser_side_mirrors(rig))
        res = render_radiance_pixels(spec, pixels_xy, spp=int(self.spp), seed=int(seed),
                                     scale=1.0, max_bounces=2, thin_lens=True, laser_on=True)
        image, _, _ = sensor_image(rig, res, noise="none",
                                   exposure_fraction=exposure_fraction)
        return image

    def _exposure_fraction(self, result) -> float:
        """The real image's stripe brightness as a fraction of full scale (the twin is exposed
        to match: saturation and the detector's threshold then act alike)."""
        full = float(2 ** self.design.sensor.bit_depth - 1)
        vals = np.concatenate([v.intensity[v.valid] for v in result.views.values()])
        # a compensated view's points moved onto rays whose own peak was elsewhere: NaN there
        vals = vals[np.isfinite(vals)]
        if vals.size == 0:
            return 0.8
        return float(np.clip(np.percentile(vals, 99.9) / full, 0.05, 1.0))

    # -- the hook ----------------------------------------------------------------------------
    @staticmethod
    def _profile(result, *, fine: bool = False):
        """The section's profile from every view's valid points: smoothed as their noise asks
        (:func:`section_profile`), or ``fine``: over 1° whatever their noise, every point kept
        (the corners' faces are fitted on it: a noisy profile's wide smoothing rounds them)."""
        pts = [v.points_meas_mm[v.valid, :2] for v in result.views.values()]
        pts = np.concatenate(pts) if pts else np.zeros((0, 2))
        if fine:
            return section_profile(pts, smooth_deg=1.0, noise_target_um=None)
        return section_profile(pts, smooth_deg=1.0)

    def observe(self, result, *, z_mm: float, origin_mm=(0.0, 0.0)) -> None:
        """Record a section of the scan before any is corrected: its stage ``z_mm`` and its
        profile (``result`` measured about ``origin_mm`` of the base frame).  Sections are
        then corrected in the order they were observed."""
        if self.axial_reach_mm <= 0:
            return
        try:
            prof = self._profile(result)
        except ValueError:
            prof = None
        if prof is not None and np.any(origin_mm):
            prof = dataclasses.replace(prof, center_mm=prof.center_mm + np.asarray(origin_mm))
        self._observed.append((float(z_mm), prof, np.asarray(origin_mm, float)))

    def passes(self) -> int:
        """How many times the measuring loop corrects the scan: :attr:`axial_passes` when
        sections were observed with a neighbour within reach, else 1."""
        zs = [z for z, p, _ in self._observed if p is not None]
        near = any(0 < abs(a - b) <= self.axial_reach_mm + 1e-9 for a in zs for b in zs)
        return int(self.axial_passes) if near else 1

    def restart(self) -> None:
        """Forget the observed scan and the sections corrected (the log keeps its times and
        the inputs' sensitivity) before the next pass observes the corrected scan."""
        self._observed = []
        self.log.sections = []

    def _surface(self, k: int, profile):
        """Section ``k``'s twin: the profile lofted along the axis by its observed neighbours
        within :attr:`axial_reach_mm`, or straight; and the log's record of the form."""
        if self.axial_reach_mm <= 0 or k >= len(self._observed):
            return loft_mesh(profile, half_length_mm=self.half_length_mm), None
        z, own, origin = self._observed[k]
        nb = [(zj - z, dataclasses.replace(pj, center_mm=pj.center_mm - origin))
              for j, (zj, pj, _) in enumerate(self._observed)
              if j != k and pj is not None and 0 < abs(zj - z) <= self.axial_reach_mm + 1e-9]
        # the form from the observed profiles alike (a radius offset common to them cancels)
        ref = profile if own is None else dataclasses.replace(own, center_mm=own.center_mm - origin)
        form = axial_form(ref, _stencil(nb)) if nb else None
        if form is None:
            return loft_mesh(profile, half_length_mm=self.half_length_mm), None
        rec = {"neighbours_dz_mm": list(form.dz_mm),
               "curvature_median_per_mm": float(np.median(form.curvature_per_mm)),
               "slope_median": float(np.median(form.slope))}
        return loft_mesh(profile, form, half_length_mm=self.half_length_mm), rec

    def _bias(self, result, measure, plan, profile, k: int):
        """Render and measure the twin of ``profile`` (section ``k``): its surface, the log's
        record of its axial form, the twin's measurement and per view its unsmoothed bias
        ``b(θ)`` (the twin's radius − the profile's exact radius along the same ray)."""
        from lts360.recon.triangulation.inverse import plan_pixels

        surface, axial = self._surface(k, profile)
        t0 = time.perf_counter()
        image = self.render(surface, plan_pixels(plan), seed=self.seed + k,
                            exposure_fraction=self._exposure_fraction(result),
                            rig=self.rig_for(plan.cal))
        t1 = time.perf_counter()
        twin = measure(image)
        self.log.render_s += t1 - t0
        self.log.measure_s += time.perf_counter() - t1
        verts = profile.vertices_mm
        bias = {}
        for name, tv in twin.views.items():
            # A compensated measurement moved the twin's view by its §4.4 offset (and its
            # mastering) too: the twin is rendered through the very planes it is measured
            # with, so what corrects those planes' errors in the real image is no bias of its.
            exact = np.full(np.shape(tv.r_mm), np.nan)
            exact[tv.valid] = ray_radii(_compensated(verts, plan.cal, name,
                                                     getattr(twin, "compensated", False)),
                                        np.asarray(tv.theta_rad)[tv.valid],
                                        near_mm=np.asarray(tv.r_mm)[tv.valid])
            bias[name] = np.where(tv.valid, tv.r_mm - exact, np.nan)
        return surface, axial, twin, bias

    @staticmethod
    def _corner_phi(result, profile) -> dict:
        """Per view, the polar angle about the profile's centre of the profile's point on each
        ray of the grid."""
        out = {}
        for name, v in result.views.items():
            th = np.asarray(v.theta_rad)
            r = ray_radii(profile.vertices_mm, th)
            d = r[:, None] * np.column_stack([np.cos(th), np.sin(th)]) - profile.center_mm
            out[name] = np.arctan2(d[:, 1], d[:, 0])
        return out

    def _choose_corners(self, result, profile, found, twin, s_twin, entry) -> dict:
        """Per view, the θ where the sharpened twin's bias applies: the zones of the corners
        whose sharpened twin measures more like the real image (rms of real − twin radius over
        the zone ±1°) than the rounded one."""
        phi = self._corner_phi(result, profile)
        zones = {name: np.zeros(p.shape, bool) for name, p in phi.items()}
        rows = []
        for c in found:
            half = c.half_width_rad + np.radians(1.0)
            sq = {"rounded": [], "sharp": []}
            near = {}
            for name, v in result.views.items():
                near[name] = np.abs(np.angle(np.exp(1j * (phi[name] - c.phi_rad)))) <= half
                for key, tw in (("rounded", twin), ("sharp", s_twin)):
                    tv = tw.views.get(name)
                    if tv is not None:
                        d = (v.r_mm - tv.r_mm)[near[name]]
                        sq[key].append(d[np.isfinite(d)])
            rms = {k: (float(1e3 * np.sqrt(np.mean(np.concatenate(a) ** 2)))
                       if a and np.concatenate(a).size else float("nan")) for k, a in sq.items()}
            keep = bool(rms["sharp"] < rms["rounded"])
            if keep:
                for name in zones:
                    zones[name] |= near[name]
            rows.append({"phi_deg": float(np.degrees(c.phi_rad)), "turn_deg": c.turn_deg,
                         "apex_mm": [float(x) for x in c.apex_mm], "sharpened": keep,
                         "rms_rounded_um": rms["rounded"], "rms_sharp_um": rms["sharp"]})
        entry["corners"] = rows
        return zones

    def __call__(self, result, measure, plan):
        entry = {"views": {}, "skipped": None}
        self.log.sections.append(entry)
        k = len(self.log.sections) - 1
        try:
            profile = self._profile(result)
        except ValueError as exc:
            entry["skipped"] = str(exc)
            return result
        entry["profile"] = {"center_mm": profile.center_mm.tolist(),
                            "coverage": profile.coverage,
                            "largest_gap_deg": profile.largest_gap_deg,
                            # the points' noise, the smoothing it asked for, the outliers dropped
                            "noise_um": profile.noise_um, "smooth_deg": profile.smooth_deg,
                            "n_outliers": profile.n_outliers}
        surface, axial, twin, bias = self._bias(result, measure, plan, profile, k)
        entry["axial"] = axial
        zones, s_bias = {}, {}
        if self.corners:
            fine = self._profile(result, fine=True) if profile.smooth_deg > 1.0 else profile
            sharp, found = sharpen_corners(fine)
            if found:
                s_surface, _, s_twin, s_bias = self._bias(result, measure, plan, sharp, k)
                zones = self._choose_corners(result, profile, found, twin, s_twin, entry)
                if any(z.any() for z in zones.values()):
                    profile, surface, twin = sharp, s_surface, s_twin
            else:
                entry["corners"] = []
        if self.input_u and not self.log.inputs:
            self._input_sensitivity(result, measure, plan, profile, twin, surface)
        grid = result.grid
        step = grid.theta_step_rad
        size = max(1, int(round(np.radians(self.smooth_deg) / step)))
        narrow = max(1, int(round(np.radians(CORNER_SMOOTH_DEG) / step)))
        wrap = bool(grid.is_full_turn)
        views = {}
        for name, v in result.views.items():
            if name not in bias:
                views[name] = v
                continue
            b = bias[name]
            b_s, count = _nan_smooth(b, size, wrap)
            zone = zones.get(name)
            if zone is not None and zone.any() and name in s_bias:
                b_n, count_n = _nan_smooth(s_bias[name], narrow, wrap)
                b = np.where(zone, s_bias[name], b)
                b_s = np.where(zone, b_n, b_s)
                count = np.where(zone, count_n, count)
            ok = v.valid & np.isfinite(b_s)
            resid = (b - b_s)[np.isfinite(b) & np.isfinite(b_s)]
            sd = float(np.std(resid)) if resid.size > 2 else float("nan")
            u = float(sd / np.sqrt(np.median(count[ok]))) if ok.any() else float("nan")
            views[name] = dataclasses.replace(v, r_mm=np.where(ok, v.r_mm - b_s, v.r_mm))
            entry["views"][name] = {
                "mean_bias_um": float(1e3 * np.mean(b_s[ok])) if ok.any() else 0.0,
                "bias_range_um": (float(1e3 * np.ptp(b_s[ok])) if ok.any() else 0.0),
                "n_corrected": int(ok.sum()), "n_uncorrected": int((v.valid & ~ok).sum()),
                "u_render_um": 1e3 * u if np.isfinite(u) else 0.0,
                # the correction itself, per corrected point: θ (rad) and the bias removed (mm)
                "theta_rad": np.asarray(v.theta_rad)[ok], "bias_mm": b_s[ok]}
        return dataclasses.replace(result, views=views)

    def _view_bias_um(self, twin, verts) -> dict[str, float]:
        """Each view's mean bias (µm) in a twin measurement of the prism ``verts``."""
        out = {}
        for name, tv in twin.views.items():
            exact = ray_radii(verts, tv.theta_rad, near_mm=tv.r_mm)
            b = (tv.r_mm - exact)[tv.valid]
            b = b[np.isfinite(b)]
            if b.size:
                out[name] = float(1e3 * np.mean(b))
        return out

    def _input_sensitivity(self, result, measure, plan, profile, twin, surface) -> None:
        """Render the twin again with each input moved by its u (same seed) and record how
        each view's mean bias moves (:attr:`TwinLog.inputs`)."""
        from lts360.recon.triangulation.inverse import plan_pixels

        verts = profile.vertices_mm
        base = self._view_bias_um(twin, verts)
        pixels = plan_pixels(plan)
        seed = self.seed + len(self.log.sections) - 1
        deltas: dict[str, dict[str, float]] = {name: {} for name in base}
        t0 = time.perf_counter()
        for key, u in self.input_u.items():
            design = perturbed_design(self.design, key, u)
            rig = twin_rig(plan.cal, design)
            img = self.render(surface, pixels, seed=seed,
                              exposure_fraction=self._exposure_fraction(result), rig=rig)
            moved = self._view_bias_um(measure(img), verts)
            for name in base:
                if name in moved:
                    deltas[name][key] = moved[name] - base[name]
        self.log.render_s += time.perf_counter() - t0
        self.log.inputs = {name: {"by_input_um": d,
                                  "u_um": float(np.sqrt(sum(v * v for v in d.values())))}
                           for name, d in deltas.items()}


def twin_corrected(result, cal: Calibration, grid, twin: TwinCorrector, *,
                   compensate: bool = False, peak: str = "centroid"):
    """``result`` — one image measured by :func:`~lts360.recon.triangulation.inverse.
    inverse_triangulate` with ``cal`` on ``grid`` (``compensate`` as it was measured) — with its
    line-centre bias removed by ``twin``: the twin image is measured by that same function."""
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse

    plan = plan_inverse(cal, grid)

    def measure(img):
        return inverse_triangulate(img, cal, grid, peak=peak, plan=plan, compensate=compensate)

    return twin(result, measure, plan)


def twin_corrected_raw(result, cal: Calibration, grid, twin: TwinCorrector, *,
                       peak: str = "centroid"):
    """A round reference's uncompensated measurement ``result`` (on ``grid``) with its
    line-centre bias removed by ``twin``, returned as raw radii (``r_raw_mm``), for the
    mastering fit (:func:`lts360.recon.calibration.compensation.master_fit`): the masters then
    set what the twin leaves, not the bias the twin removes from every later measurement."""
    fixed = twin_corrected(result, cal, grid, twin, peak=peak)
    views = {n: dataclasses.replace(v, r_raw_mm=np.where(np.isfinite(v.r_mm), v.r_mm,
                                                         v.r_raw_mm))
             for n, v in fixed.views.items()}
    return dataclasses.replace(fixed, views=views)
