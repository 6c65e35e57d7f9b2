"""Model-based line-centre bias correction: measure the twin of the section with the same
plan, and subtract what the chain does to a profile whose radii are known exactly.

For each section: the measured points of all views, each view moved by its offset from the
others where they measured the same rays (:func:`~lts360.twin.profile.view_offsets`: a
calibration's error, a view's own bias), give one seam-free profile; each view's twin is that
profile placed where the view measured the section (:func:`~lts360.twin.profile.
placed_profile`: moved by the view's offset and bent by its own points' smooth departure, not
by their point-scale ripple).  One profile of all views' points as they are would be a
patchwork whose seams lie at each view's ends, where its correction is largest: with mirror
planes 50 µm off it moved the corrections by ~2 µm.  Each view's prism is rendered noise-free
through the calibrated rig with the rig file's optics (:mod:`lts360.twin.rig`: the camera sees it through
the calibrated mirrors, the laser lights it through them turned perpendicular to the
calibrated sheet) on that view's pixels of the plan only (:func:`view_pixels`, one loaded
scene, its vertices moved from view to view), the parts put together into one twin image,
which is measured by the very function (same grid, windows, detector, compensation,
rejection) that measured the real image.  Per view and θ the bias is
``b = r_twin_measured − r_twin_exact`` (the exact radius of the view's prism along the same
ray), smoothed along θ over ``smooth_deg`` (the twin's render noise), and the real radii
become ``r − b``.  A valid point farther than ``smooth_deg / 2`` from any twin estimate of its
view keeps its radius and is counted as uncorrected.

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
import weakref
from dataclasses import dataclass, field

import numpy as np

from lts360.recon.model import Calibration
from lts360.scenes.materials import get_material
from lts360.scenes.rig import Rig
from lts360.twin.corners import sharpen_corners
from lts360.twin.profile import (
    axial_form,
    loft_mesh,
    placed_profile,
    ray_radii,
    section_profile,
    view_offsets,
)
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


def _uncompensated(verts_mm: np.ndarray, cal, name: str, compensate: bool) -> np.ndarray:
    """The inverse of :func:`_compensated`: where the profile ``verts_mm`` (n, 2), as view
    ``name``'s compensated measurement reads it, lies in that view's own (uncompensated)
    measurement: the translation taken off, then the radii ``(ρ − radial offset) / scale``."""
    from lts360.recon.triangulation.inverse import compensation_of

    kw = compensation_of(cal, name, compensate)
    if not kw:
        return verts_mm
    v = verts_mm - kw.get("offset_mm", np.zeros(2))
    rho = np.hypot(*v.T)
    return v * (((rho - kw["radial_offset_mm"]) / kw["scale"]) / rho)[:, None]


def _placed(mesh, cal, name: str, compensate: bool):
    """``mesh`` (view ``name``'s twin, as its compensated measurement reads it) out of the
    view's compensation: the twin is rendered through the calibrated planes as they are.  The
    same faces (a loaded scene is reused with its vertices moved); ``mesh`` itself when the
    view is not compensated."""
    import trimesh

    if not compensate:
        return mesh
    v = np.array(mesh.vertices, dtype=float)
    v[:, :2] = _uncompensated(v[:, :2], cal, name, compensate)
    return trimesh.Trimesh(vertices=v, faces=mesh.faces, process=False)


#: Per plan, each view's pixels (the plan's own, split by view; dies with the plan).
_VIEW_PIXELS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def view_pixels(plan, *, margin_px: int = 4) -> dict:
    """Each view's pixels of ``plan``: what the view's twin render needs, the pixels of
    :func:`~lts360.recon.triangulation.inverse.plan_pixels` (the same rule: the 4 × 4
    neighbourhood of each grid point's projection widened by ``margin_px``) split by the view
    that reads them (a pixel two views read goes to the first).  Each view's box is built on
    its own bounding box, not the whole image."""
    from scipy.ndimage import maximum_filter1d

    out = _VIEW_PIXELS.get(plan)
    if out is not None:
        return out
    w, h = plan.cal.image_size
    r = 2 + int(margin_px)
    seen = np.zeros((h, w), bool)
    out = {}
    for name, vp in plan.views.items():  # as plan_pixels, on the view's bounding box
        uv = vp.uv.reshape(-1, 2)
        u, v = uv[:, 0], uv[:, 1]
        # floor(u) in [-2, w + 1) is u in [-2, w + 1) (NaN fails it); floor then clip to the
        # image is clip then truncate
        with np.errstate(invalid="ignore"):
            ok = (u >= -2) & (u < w + 1) & (v >= -2) & (v < h + 1)
        mx = np.clip(u[ok], 0, w - 1).astype(np.int64)
        my = np.clip(v[ok], 0, h - 1).astype(np.int64)
        if not mx.size:
            out[name] = np.zeros((0, 2), np.int64)
            continue
        x0, y0 = max(int(mx.min()) - r, 0), max(int(my.min()) - r, 0)
        x1, y1 = min(int(mx.max()) + r + 1, w), min(int(my.max()) + r + 1, h)
        m = np.zeros((y1 - y0, x1 - x0), np.uint8)
        m[my - y0, mx - x0] = 1
        for axis in (0, 1):
            m = maximum_filter1d(m, 2 * r + 1, axis=axis, mode="constant", cval=0)
        ys, xs = np.nonzero(m)
        ys, xs = ys + y0, xs + x0
        new = ~seen[ys, xs]
        seen[ys[new], xs[new]] = True
        out[name] = np.column_stack([xs[new], ys[new]])
    _VIEW_PIXELS[plan] = out
    return out


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
    sampler : str
        The twin render's sampler: ``keyed`` (default:
        :class:`~lts360.simulator.keyed_sampler.KeyedSampler`, a pixel's samples a function of
        the pixel and the seed alone: the twins of one image with two calibrations, whose
        plans read slightly different pixels, share their render noise where they overlap;
        with Mitsuba's ``multijitter`` they drew it independently and at 64 spp their mean
        corrections differed by up to 7 µm (direct view, half-scale Ø12 gauge, mirror planes
        50 µm off), keyed ≤ 0.4 µm) or one of Mitsuba's (:data:`lts360.simulator.render.SAMPLERS`).
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
    sampler: str = "keyed"
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
        from lts360.simulator.render import SAMPLERS

        if self.sampler not in SAMPLERS:
            raise ValueError(f"twin sampler must be one of {', '.join(SAMPLERS)}, got "
                             f"{self.sampler!r}")
        if not 0 < self.smooth_deg <= 30:
            raise ValueError(f"twin smooth_deg must be in (0, 30], got {self.smooth_deg}")
        if not 0 <= self.axial_reach_mm <= MAX_AXIAL_REACH_MM:
            raise ValueError(f"twin axial_reach_mm must be in [0, {MAX_AXIAL_REACH_MM:g}], got "
                             f"{self.axial_reach_mm}")
        if not 1 <= int(self.axial_passes) <= 5:
            raise ValueError(f"twin axial_passes must be in [1, 5], got {self.axial_passes}")
        self._observed: list = []  # (z_mm, profile in the base frame or None, origin)
        self._scenes = None  # the twin's loaded scenes (SceneCache), made at the first render
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
    def _radiance(self, surface, pixels_xy: np.ndarray, *, seed: int, rig: Rig):
        """The twin's radiance and laser share (W m⁻² sr⁻¹) of ``surface`` (a closed mesh, or
        a profile extruded straight) on ``pixels_xy`` only; the scene is loaded once and
        reused while only the surface's vertices move."""
        from lts360.simulator.materials import material_to_bsdf
        from lts360.simulator.render import ensure_variant, render_pixels
        from lts360.simulator.reuse import SceneCache
        from lts360.simulator.scene import SceneSpec

        ensure_variant()
        mesh = (surface if hasattr(surface, "faces")
                else loft_mesh(surface, half_length_mm=self.half_length_mm))
        spec = SceneSpec(rig, (("object", mesh,
                                     material_to_bsdf(get_material(self.material))),),
                         laser_mirrors=laser_side_mirrors(rig))
        kw = dict(spp=int(self.spp), scale=1.0, max_bounces=2, thin_lens=True, laser_on=True,
                  sampler=self.sampler)
        if self._scenes is None:
            self._scenes = SceneCache(max_scenes=2)
        rad, las, _ = render_pixels(spec, pixels_xy, seed=int(seed),
                                    prepared=self._scenes.prepare(spec, **kw), **kw)
        return rad, las

    def render(self, surface, pixels_xy: np.ndarray, *, seed: int, exposure_fraction: float,
               rig: Rig | None = None) -> np.ndarray:
        """The twin's noise-free digital image of ``surface`` (a closed mesh, or a profile
        extruded straight; only ``pixels_xy`` rendered; ``rig`` defaults to :attr:`rig`)."""
        return self.render_views({"all": (surface, pixels_xy)}, seed=seed,
                                 exposure_fraction=exposure_fraction, rig=rig)

    def render_views(self, parts: dict, *, seed: int, exposure_fraction: float,
                     rig: Rig | None = None) -> np.ndarray:
        """One twin image made of parts: ``parts`` maps a view to ``(surface, pixels_xy)``,
        each surface rendered on its view's pixels only (the same seed), then the image
        exposed once as a whole (``exposure_fraction``: its brightest laser pixels, the 99.9th
        percentile, as a fraction of full scale)."""
        from lts360.simulator.frame import sensor_image
        from lts360.simulator.render import RenderResult, require_variant

        rig = self.rig if rig is None else rig
        cam = rig.camera
        radiance = np.zeros((cam.height_px, cam.width_px), np.float32)
        laser = np.zeros_like(radiance)
        for surface, px in parts.values():
            px = np.asarray(px, np.int64).reshape(-1, 2)
            rad, las = self._radiance(surface, px, seed=seed, rig=rig)
            radiance[px[:, 1], px[:, 0]] = rad
            laser[px[:, 1], px[:, 0]] = las
        total = RenderResult(radiance_W_m2_sr=radiance, laser_W_m2_sr=laser, K=cam.K,
                             variant=require_variant(), spp=int(self.spp), seed=int(seed),
                             seconds=0.0)
        image, _, _ = sensor_image(rig, total, noise="none",
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
    def _offsets(result) -> dict:
        """Each view's offset from the others where they measured the same rays
        (:func:`~lts360.twin.profile.view_offsets`, mm): a calibration's error (a mirror plane
        50 µm off moves its view's points ~0.1 mm) and each view's own bias."""
        return view_offsets(np.asarray(result.grid.theta_rad),
                            {n: np.where(v.valid, v.r_mm, np.nan)
                             for n, v in result.views.items()})

    @staticmethod
    def _profile(result, offsets: dict | None = None, *, fine: bool = False):
        """The section's profile from every view's valid points, each view moved by minus
        its ``offsets`` (the views aligned: no seam where one view's points give way to
        another's): smoothed as their noise asks (:func:`section_profile`), or ``fine``: over
        1° whatever their noise, every point kept (the corners' faces are fitted on it: a
        noisy profile's wide smoothing rounds them)."""
        offsets = offsets or {}
        pts = [v.points_meas_mm[v.valid, :2] - offsets.get(n, np.zeros(2))
               for n, v in result.views.items()]
        pts = np.concatenate(pts) if pts else np.zeros((0, 2))
        if fine:
            return section_profile(pts, smooth_deg=1.0, noise_target_um=None)
        return section_profile(pts, smooth_deg=1.0)

    @staticmethod
    def _view_profiles(result, profile, offsets: dict) -> dict:
        """Each view's profile: the views' common ``profile`` placed where the view measured
        the section (:func:`~lts360.twin.profile.placed_profile`: moved by its offset, bent by
        its own points' smooth departure)."""
        return {n: placed_profile(profile, v.points_meas_mm[v.valid, :2], offsets[n])
                for n, v in result.views.items() if v.valid.any()}

    def observe(self, result, *, z_mm: float, origin_mm=(0.0, 0.0)) -> None:
        """Record a section of the scan before any is corrected: its stage ``z_mm`` and its
        profile (``result`` measured about ``origin_mm`` of the base frame).  Sections are
        then corrected in the order they were observed."""
        if self.axial_reach_mm <= 0:
            return
        try:
            # as measured, not aligned by the views' offsets: the offsets are each section's
            # own (a shiny surface's views disagree by ~20 µm, differently from section to
            # section), and aligning by them gave neighbours 0.5 mm apart false slopes and
            # curvatures (the alu pipe's crest +40 µm); a calibration's error is the same
            # in every section of a scan and cancels in the form as measured
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

    def _surface(self, k: int, profile, views: dict | None = None):
        """Section ``k``'s twin: the profile lofted along the axis by its observed neighbours
        within :attr:`axial_reach_mm`, or straight; and the log's record of the form.  With
        ``views`` (name -> that view's profile) a dict of surfaces instead, each view's profile
        lofted by the form read from ``profile``."""
        if views is not None:
            form, rec = self._form(k, profile)
            return {n: loft_mesh(p, form, half_length_mm=self.half_length_mm)
                    for n, p in views.items()}, rec
        form, rec = self._form(k, profile)
        return loft_mesh(profile, form, half_length_mm=self.half_length_mm), rec

    def _form(self, k: int, profile):
        """Section ``k``'s axial form from its observed neighbours (``None``: straight) and
        the log's record of it."""
        if self.axial_reach_mm <= 0 or k >= len(self._observed):
            return None, None
        z, own, origin = self._observed[k]
        nb = [(zj - z, dataclasses.replace(pj, center_mm=pj.center_mm - origin))
              for j, (zj, pj, _) in enumerate(self._observed)
              if j != k and pj is not None and 0 < abs(zj - z) <= self.axial_reach_mm + 1e-9]
        # the form from the observed profiles alike (a radius offset common to them cancels)
        ref = profile if own is None else dataclasses.replace(own, center_mm=own.center_mm - origin)
        form = axial_form(ref, _stencil(nb)) if nb else None
        if form is None:
            return None, None
        return form, {"neighbours_dz_mm": list(form.dz_mm),
                      "curvature_median_per_mm": float(np.median(form.curvature_per_mm)),
                      "slope_median": float(np.median(form.slope))}

    def _parts(self, result, plan, surfaces: dict) -> dict:
        """Per view: its twin's surface (``surfaces``, as its compensated measurement reads
        it) out of its compensation (:func:`_placed`), and the view's pixels
        (:meth:`render_views`' parts): each view's twin image lies where the real one does,
        whatever the calibration's errors."""
        pixels = view_pixels(plan)
        comp = bool(getattr(result, "compensated", False))
        return {name: (_placed(surfaces[name], plan.cal, name, comp), px)
                for name, px in pixels.items() if len(px) and name in surfaces}

    def _bias(self, result, measure, plan, profile, views: dict, k: int):
        """Render and measure section ``k``'s twin, each view's twin its own profile
        (``views``: name -> :func:`~lts360.twin.profile.placed_profile`; ``profile`` the views'
        common one, whose neighbours give the axial form): the log's record of the form, the
        twin's measurement, per view its unsmoothed bias ``b(θ)`` (the twin's radius − the
        exact radius of the view's profile along the same ray) and the parts rendered."""
        surfaces, axial = self._surface(k, profile, views)
        parts = self._parts(result, plan, surfaces)
        t0 = time.perf_counter()
        image = self.render_views(parts, seed=self.seed + k,
                                  exposure_fraction=self._exposure_fraction(result),
                                  rig=self.rig_for(plan.cal))
        t1 = time.perf_counter()
        twin = measure(image)
        self.log.render_s += t1 - t0
        self.log.measure_s += time.perf_counter() - t1
        bias = {}
        for name, tv in twin.views.items():
            # The twin of each view lies where that view measured the section, moved out of
            # its compensation (§4.4, mastering) and measured with it: its exact radius is its
            # profile's, as the compensated measurement reads it.
            exact = np.full(np.shape(tv.r_mm), np.nan)
            exact[tv.valid] = ray_radii(views.get(name, profile).vertices_mm,
                                        np.asarray(tv.theta_rad)[tv.valid],
                                        near_mm=np.asarray(tv.r_mm)[tv.valid])
            bias[name] = np.where(tv.valid, tv.r_mm - exact, np.nan)
        return axial, twin, bias, parts

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
            offsets = self._offsets(result)
            profile = self._profile(result, offsets)
            views = self._view_profiles(result, profile, offsets)
        except ValueError as exc:
            entry["skipped"] = str(exc)
            return result
        entry["profile"] = {"center_mm": profile.center_mm.tolist(),
                            "coverage": profile.coverage,
                            "largest_gap_deg": profile.largest_gap_deg,
                            # the points' noise, the smoothing it asked for, the outliers dropped
                            "noise_um": profile.noise_um, "smooth_deg": profile.smooth_deg,
                            "n_outliers": profile.n_outliers,
                            # each view's offset from the others (µm): its twin is moved so
                            "view_offsets_um": {n: (1e3 * t).tolist() for n, t in offsets.items()}}
        axial, twin, bias, parts = self._bias(result, measure, plan, profile, views, k)
        entry["axial"] = axial
        zones, s_bias = {}, {}
        if self.corners:
            fine = (self._profile(result, offsets, fine=True) if profile.smooth_deg > 1.0
                    else profile)
            sharp, found = sharpen_corners(fine)
            if found:
                # each view's sharp twin: the common one's, moved by the view's offset (a
                # view's own points near a corner it sees at grazing incidence round it more)
                s_views = {n: dataclasses.replace(sharp, center_mm=sharp.center_mm + offsets[n])
                           for n in views}
                _, s_twin, s_bias, s_parts = self._bias(result, measure, plan, sharp, s_views, k)
                zones = self._choose_corners(result, profile, found, twin, s_twin, entry)
                if any(z.any() for z in zones.values()):
                    profile, views, twin, parts = sharp, s_views, s_twin, s_parts
            else:
                entry["corners"] = []
        if self.input_u and not self.log.inputs:
            self._input_sensitivity(result, measure, plan, views, twin, parts)
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

    def _view_bias_um(self, twin, views: dict) -> dict[str, float]:
        """Each view's mean bias (µm) in a twin measurement of its profile (``views``)."""
        out = {}
        for name, tv in twin.views.items():
            if name not in views:
                continue
            exact = ray_radii(views[name].vertices_mm, tv.theta_rad, near_mm=tv.r_mm)
            b = (tv.r_mm - exact)[tv.valid]
            b = b[np.isfinite(b)]
            if b.size:
                out[name] = float(1e3 * np.mean(b))
        return out

    def _input_sensitivity(self, result, measure, plan, views, twin, parts) -> None:
        """Render the twin (its ``parts``, :meth:`render_views`) again with each input moved by
        its u (same seed) and record how each view's mean bias moves (:attr:`TwinLog.inputs`)."""
        base = self._view_bias_um(twin, views)
        seed = self.seed + len(self.log.sections) - 1
        deltas: dict[str, dict[str, float]] = {name: {} for name in base}
        t0 = time.perf_counter()
        for key, u in self.input_u.items():
            design = perturbed_design(self.design, key, u)
            rig = twin_rig(plan.cal, design)
            img = self.render_views(parts, seed=seed,
                                    exposure_fraction=self._exposure_fraction(result), rig=rig)
            moved = self._view_bias_um(measure(img), views)
            for name in base:
                if name in moved:
                    deltas[name][key] = moved[name] - base[name]
        self.log.render_s += time.perf_counter() - t0
        self.log.inputs = {name: {"by_input_um": d,
                                  "u_um": float(np.sqrt(sum(v * v for v in d.values())))}
                           for name, d in deltas.items()}


def twin_corrected(result, cal: Calibration, grid, twin: TwinCorrector, *,
                   compensate: bool = False, peak: str = "centroid", plan=None):
    """``result`` — one image measured by :func:`~lts360.recon.triangulation.inverse.
    inverse_triangulate` with ``cal`` on ``grid`` (``compensate`` as it was measured) — with its
    line-centre bias removed by ``twin``: the twin image is measured by that same function
    (with ``plan``, the plan ``result`` was measured with, if the caller holds it: for ``cal``
    and ``grid``, not made again)."""
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse

    if plan is None:
        plan = plan_inverse(cal, grid)
    elif plan.cal is not cal or plan.grid is not grid:
        raise ValueError("twin_corrected: the plan is not for this calibration and grid")

    def measure(img):
        return inverse_triangulate(img, cal, grid, peak=peak, plan=plan, compensate=compensate)

    return twin(result, measure, plan)


def twin_corrected_raw(result, cal: Calibration, grid, twin: TwinCorrector, *,
                       peak: str = "centroid", plan=None):
    """A round reference's uncompensated measurement ``result`` (on ``grid``) with its
    line-centre bias removed by ``twin``, returned as raw radii (``r_raw_mm``), for the
    mastering fit (:func:`lts360.recon.calibration.compensation.master_fit`): the masters then
    set what the twin leaves, not the bias the twin removes from every later measurement.
    ``plan``: as :func:`twin_corrected`."""
    fixed = twin_corrected(result, cal, grid, twin, peak=peak, plan=plan)
    views = {n: dataclasses.replace(v, r_raw_mm=np.where(np.isfinite(v.r_mm), v.r_mm,
                                                         v.r_raw_mm))
             for n, v in fixed.views.items()}
    return dataclasses.replace(fixed, views=views)
