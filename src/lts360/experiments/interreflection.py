"""Interreflected laser light checked against Mitsuba's own ``path`` integrator and closed forms.

The laser integrator's interreflection term (``max_scatter``) is compared, sample for sample
statistics, with Mitsuba's ``path`` integrator lighting the same scene with the sheet as an
emitter (:mod:`lts360.simulator.sheet_emitter`).  Both are run on the same camera rays of a
small pinhole view, one Monte Carlo lane per sample, so every pixel gets its mean and its
sample variance:

* ours: ``max_scatter = 1`` minus ``max_scatter = 0`` with the same sampler seed (the direct
  term is the same number in both, so the difference is the interreflection estimate alone);
* Mitsuba: ``max_depth = 3`` minus ``max_depth = 2`` with the same seed (one more vertex of
  next-event estimation).

Scenes (no mirrors: the ``path`` integrator cannot connect a delta sheet through one):

* ``corner``: a white Lambertian inside corner (two perpendicular 60 mm faces) lit by a sheet
  perpendicular to its edge: each face's stripe lights the other face;
* ``cylinder``: a shiny Ø20 mm cylinder (machined-aluminium-like blend, GGX α = 0.12) beside a
  matte wall: the cylinder's glossy lobe throws a secondary stripe onto the wall and the wall
  lights the cylinder back;
* ``cavity``: the inside of a white sphere lit from its centre (the integrating sphere): after
  ``k`` bounces the irradiance is ``ρᵏ Φ / (4πR²)`` everywhere, a closed form for every
  ``max_scatter``.

Lengths in mm; radiance in W m⁻² sr⁻¹.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.simulator.integrator import LaserParams

__all__ = [
    "ComponentComparison",
    "ValidationScene",
    "cavity_radiance_W_m2_sr",
    "cavity_scene",
    "compare_components",
    "component_samples",
    "corner_scatter_radiance_W_m2_sr",
    "corner_scene",
    "lane_values",
    "shiny_cylinder_scene",
]


@dataclass(frozen=True)
class ValidationScene:
    """A mirror-free scene, its sheet and a pinhole view (lengths in mm)."""

    name: str
    shapes: dict
    laser: LaserParams
    eye_mm: tuple[float, float, float]
    target_mm: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float


def _diffuse(albedo: float) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "spectrum", "value": float(albedo)}}


def _rectangle(center, u_half, v_half) -> dict:
    """A rectangle with half-axes ``u_half``, ``v_half`` (its normal is ``u × v``); its
    ``to_world`` is a 4×4 list that :func:`load` turns into a Mitsuba transform."""
    u, v = np.asarray(u_half, float), np.asarray(v_half, float)
    n = np.cross(u, v)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = u, v, n / np.linalg.norm(n), center
    return {"type": "rectangle", "to_world": T.tolist()}


def _sheet(origin, direction, half_fan_deg, waist_mm, power_W=1e-3) -> LaserParams:
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return LaserParams(origin_mm=tuple(map(float, origin)), direction=tuple(map(float, d)),
                       normal=(0.0, 0.0, 1.0), half_fan_rad=math.radians(half_fan_deg),
                       fan_profile="flat", waist_mm=float(waist_mm), waist_distance_mm=70.0,
                       rayleigh_range_mm=1.0e4, power_W=float(power_W))


def corner_scene(albedo: float = 0.8, waist_mm: float = 1.0) -> ValidationScene:
    """White inside corner: face A ``x = 0`` (normal +x) and face B ``y = 0`` (normal +y), both
    ``y`` resp. ``x`` in [-1, 60] and ``z`` in [-30, 30]; the sheet ``z = 0`` from (50, 50, 0)
    along the diagonal, flat fan ±30° (stripes on both faces out to 36.6 mm from the edge)."""
    shapes = {
        "face_a": _rectangle((0.0, 29.5, 0.0), (0.0, 30.5, 0.0), (0.0, 0.0, 30.0)) | {"bsdf": _diffuse(albedo)},
        "face_b": _rectangle((29.5, 0.0, 0.0), (0.0, 0.0, 30.0), (30.5, 0.0, 0.0)) | {"bsdf": _diffuse(albedo)},
    }
    return ValidationScene("corner", shapes, _sheet((50.0, 50.0, 0.0), (-1.0, -1.0, 0.0), 30.0, waist_mm),
                           eye_mm=(55.0, 55.0, 30.0), target_mm=(8.0, 8.0, 0.0), up=(0.0, 0.0, 1.0),
                           fov_deg=50.0)


def shiny_cylinder_scene(alpha: float = 0.12, specular_weight: float = 0.55,
                         diffuse_reflectance: float = 0.30, wall_albedo: float = 0.8
                         ) -> ValidationScene:
    """A Ø20 mm cylinder (axis z, blend of Lambert and a GGX aluminium conductor, η + iκ =
    1.49 + 7.82i) beside a matte wall ``x = 14`` (normal −x), the sheet from (0, −60, 0)
    along +y, flat fan ±25°."""
    conductor = {"type": "roughconductor", "distribution": "ggx", "alpha": float(alpha),
                 "eta": {"type": "spectrum", "value": 1.49}, "k": {"type": "spectrum", "value": 7.82}}
    metal = {"type": "blendbsdf", "weight": float(specular_weight),
             "bsdf_0": _diffuse(diffuse_reflectance), "bsdf_1": conductor}
    shapes = {
        "cylinder": {"type": "cylinder", "radius": 10.0, "p0": [0.0, 0.0, -20.0],
                     "p1": [0.0, 0.0, 20.0], "bsdf": metal},
        "wall": _rectangle((14.0, -10.0, 0.0), (0.0, 0.0, 20.0), (0.0, 30.0, 0.0)) | {"bsdf": _diffuse(wall_albedo)},
    }
    return ValidationScene("cylinder", shapes, _sheet((0.0, -60.0, 0.0), (0.0, 1.0, 0.0), 25.0, 1.0),
                           eye_mm=(-35.0, -55.0, 30.0), target_mm=(4.0, -6.0, 0.0),
                           up=(0.0, 0.0, 1.0), fov_deg=45.0)


def cavity_scene(albedo: float = 0.8, radius_mm: float = 50.0, waist_mm: float = 5.0) -> ValidationScene:
    """Inside of a white sphere (normals inwards) with the sheet's apex at its centre (flat fan
    over the full circle: all the power lands on the sphere, as a band about its equator);
    the view looks from the centre at the pole."""
    shapes = {"sphere": {"type": "sphere", "radius": float(radius_mm), "flip_normals": True,
                         "bsdf": _diffuse(albedo)}}
    return ValidationScene("cavity", shapes, _sheet((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 180.0, waist_mm),
                           eye_mm=(0.0, 0.0, 0.0), target_mm=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0),
                           fov_deg=60.0)


def cavity_radiance_W_m2_sr(albedo: float, radius_mm: float, power_W: float, max_scatter: int) -> float:
    """Interreflected radiance anywhere inside a Lambertian sphere whose wall receives
    ``power_W`` directly: ``(ρ/π) Σ_{k=1..N} ρᵏ Φ/(4πR²)`` (every point of a sphere sees
    every area element with ``cosθ cosθ' / r² = 1/(4R²)``)."""
    series = sum(albedo ** k for k in range(1, max_scatter + 1))
    return albedo / math.pi * series * power_W / (4.0 * math.pi * radius_mm ** 2) * 1.0e6


def corner_scatter_radiance_W_m2_sr(vs: ValidationScene, x_mm: float, z_mm: float,
                                    albedo: float = 0.8, n_s: int = 4000, n_h: int = 241) -> float:
    """Once-interreflected radiance at the point ``(x, 0, z)`` of the corner's face B: the
    irradiance integral over face A's stripe,
    ``E(y) = ∫∫ (ρ/π) E_A(0, s, h) · cosθ_A cosθ_B / r² ds dh`` with ``cosθ_A = x/r``,
    ``cosθ_B = s/r``, ``r² = x² + s² + (z − h)²``, and ``E_A`` the sheet's irradiance on the
    face (normal-to-beam irradiance times the incidence cosine); then ``L = (ρ/π) E(y)``.
    Quadrature: midpoint in ``s`` over the lit part of face A, trapezoid in ``h`` over ±6 w."""
    las = vs.laser
    O = np.asarray(las.origin_mm)
    d = np.asarray(las.direction)
    e2 = np.cross(np.asarray(las.normal), d)
    s_max = O[1] - O[0] * math.tan(math.pi / 4.0 - las.half_fan_rad)  # fan edge on face A
    ds = s_max / n_s
    s = (np.arange(n_s) + 0.5) * ds
    rel = np.stack([-O[0] + 0 * s, s - O[1], 0 * s], axis=1)  # apex → (0, s, 0)
    rho = np.linalg.norm(rel, axis=1)
    phi = np.arctan2(rel @ e2, rel @ d)
    fan = np.where(np.abs(phi) <= las.half_fan_rad, 0.5 / las.half_fan_rad, 0.0)
    w = las.waist_mm * np.sqrt(1.0 + ((rho - las.waist_distance_mm) / las.rayleigh_range_mm) ** 2)
    cos_inc = O[0] / rho  # beam · (−n_A), n_A = +x
    h = np.linspace(-6.0, 6.0, n_h)[None, :] * w[:, None]
    across = math.sqrt(2.0 / math.pi) / w[:, None] * np.exp(-2.0 * (h / w[:, None]) ** 2)
    E_a = las.power_W * (fan / rho * cos_inc)[:, None] * across  # W/mm²
    r2 = x_mm ** 2 + s[:, None] ** 2 + (z_mm - h) ** 2
    kernel = x_mm * s[:, None] / r2 ** 2
    E_b = albedo / math.pi * np.trapezoid(E_a * kernel, h, axis=1).sum() * ds
    return albedo / math.pi * E_b * 1.0e6


def load(vs: ValidationScene, *, emitter: bool):
    """The Mitsuba scene (with the ``laser_sheet`` emitter when ``emitter``)."""
    import mitsuba as mi

    d = {"type": "scene"}
    for key, shape in vs.shapes.items():
        d[key] = dict(shape)
        if "to_world" in shape:
            d[key]["to_world"] = mi.ScalarTransform4f(shape["to_world"])
    if emitter:
        from lts360.simulator.sheet_emitter import register, sheet_emitter_dict

        register()
        d["sheet"] = sheet_emitter_dict(vs.laser)
    return mi.load_dict(d)


def pinhole_rays(vs: ValidationScene, width: int, height: int, spp: int, seed: int):
    """Origins and unit directions ``(n, 3)`` of ``width·height·spp`` jittered pinhole rays,
    pixel by pixel (row-major), ``spp`` consecutive lanes per pixel."""
    rng = np.random.default_rng(seed)
    eye = np.asarray(vs.eye_mm, float)
    fwd = np.asarray(vs.target_mm, float) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(vs.up, float))
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    t = math.tan(math.radians(vs.fov_deg) / 2.0)
    j, i = np.divmod(np.repeat(np.arange(width * height), spp), width)
    u = (i + rng.random(i.size)) / width * 2.0 - 1.0
    v = ((j + rng.random(j.size)) / height * 2.0 - 1.0) * height / width
    dirs = fwd + t * (u[:, None] * right + v[:, None] * down)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return np.broadcast_to(eye, dirs.shape), dirs


def lane_values(scene, integrator, origins, dirs, seed: int, *, laser_aov: bool) -> np.ndarray:
    """One sample per ray: the laser AOV (ours) or the radiance (any Mitsuba integrator)."""
    import drjit as dr
    import mitsuba as mi

    n = len(dirs)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    o = mi.Point3f(*(mi.Float(np.ascontiguousarray(origins[:, k], np.float32)) for k in range(3)))
    d = mi.Vector3f(*(mi.Float(np.ascontiguousarray(dirs[:, k], np.float32)) for k in range(3)))
    L, _, aovs = integrator.sample(scene, sampler, mi.Ray3f(o, d), None, True)
    value = aovs[0] if laser_aov else L[0]
    dr.eval(value)
    return np.array(value, dtype=np.float64)


def component_samples(vs: ValidationScene, renderer: str, component: str, *, width: int,
                      height: int, spp: int, seed: int) -> np.ndarray:
    """``(height, width, spp)`` samples of one light component of the view.

    renderer : {"laser", "path"}
    component : {"direct", "scatter"}
        ``direct``: ``max_scatter = 0`` / ``max_depth = 2``; ``scatter``: the once-
        interreflected light (the difference of two runs with the same seed).
    """
    import mitsuba as mi

    from lts360.simulator.integrator import make_integrator

    if renderer not in ("laser", "path") or component not in ("direct", "scatter"):
        raise ValueError(f"renderer must be laser or path and component direct or scatter, "
                         f"got {renderer!r}, {component!r}")
    origins, dirs = pinhole_rays(vs, width, height, spp, seed)
    scene = load(vs, emitter=renderer == "path")
    if renderer == "laser":
        runs = [make_integrator(vs.laser, (), max_scatter=m) for m in (0, 1)]
    else:
        runs = [mi.load_dict({"type": "path", "max_depth": m}) for m in (2, 3)]
    lo = lane_values(scene, runs[0], origins, dirs, seed, laser_aov=renderer == "laser")
    out = lo
    if component == "scatter":
        out = lane_values(scene, runs[1], origins, dirs, seed, laser_aov=renderer == "laser") - lo
    return out.reshape(height, width, spp)


@dataclass(frozen=True)
class ComponentComparison:
    """Two renderers' estimates of one component over the same pixels.

    ``total_*`` are the sums of the per-pixel means (W m⁻² sr⁻¹ · pixels) with their standard
    errors; ``z`` per pixel is the difference of the means over its standard error;
    ``chi2_per_dof`` the mean of ``z²`` over the ``n_pixels`` pixels where either has light.
    """

    total_a: float
    total_b: float
    se_total_a: float
    se_total_b: float
    rel_diff_total: float
    chi2_per_dof: float
    n_pixels: int
    frac_abs_z_over_4: float


def compare_components(a: np.ndarray, b: np.ndarray) -> ComponentComparison:
    """Compare ``(H, W, spp)`` samples of two renderers (pixel means, sample variances)."""
    n_a, n_b = a.shape[-1], b.shape[-1]
    ma, mb = a.mean(-1), b.mean(-1)
    va, vb = a.var(-1, ddof=1) / n_a, b.var(-1, ddof=1) / n_b
    lit = (va + vb) > 0
    z = (ma - mb)[lit] / np.sqrt((va + vb)[lit])
    ta, tb = float(ma.sum()), float(mb.sum())
    return ComponentComparison(total_a=ta, total_b=tb, se_total_a=float(math.sqrt(va.sum())),
                               se_total_b=float(math.sqrt(vb.sum())),
                               rel_diff_total=(ta - tb) / tb if tb != 0 else math.inf,
                               chi2_per_dof=float(np.mean(z ** 2)) if z.size else math.nan,
                               n_pixels=int(lit.sum()),
                               frac_abs_z_over_4=float(np.mean(np.abs(z) > 4)) if z.size else math.nan)


def validate_against_path(*, width: int = 48, height: int = 32, spp: int = 512,
                          batches: dict | None = None) -> dict:
    """The interreflection-only component of both renderers on both scenes (the slow test's
    settings): per scene the :class:`ComponentComparison` of ``batches[scene]`` batches of
    ``spp`` samples per pixel (seeds 100+k for ours, 200+k for Mitsuba's)."""
    import dataclasses

    batches = batches or {"corner": 12, "cylinder": 32}
    out = {}
    for name, n in batches.items():
        vs = corner_scene() if name == "corner" else shiny_cylinder_scene()
        a = np.concatenate([component_samples(vs, "laser", "scatter", width=width, height=height,
                                              spp=spp, seed=100 + k) for k in range(n)], axis=-1)
        b = np.concatenate([component_samples(vs, "path", "scatter", width=width, height=height,
                                              spp=spp, seed=200 + k) for k in range(n)], axis=-1)
        out[name] = dataclasses.asdict(compare_components(a, b)) | {
            "width": width, "height": height, "spp": spp * n}
    return out


def secondary_stripe_figure(obj_name: str, path, *, spp: int = 64, scale: float = 0.5,
                            max_scatter: int = 1, seed: int = 0) -> dict:
    """A PNG of the object's stripe in the paper rig without and with interreflections and of
    their difference (the secondary stripes), log-scaled radiance, cropped to the lit box;
    returns the laser light's totals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec, object_meshes

    spec = SceneSpec(load_rig("paper"), object_meshes(build_object(obj_name)))
    imgs = [render_radiance(spec, spp=spp, seed=seed, scale=scale, max_scatter=m).laser_W_m2_sr
            for m in (0, max_scatter)]
    diff = np.clip(imgs[1].astype(np.float64) - imgs[0], 0.0, None)
    lit = np.argwhere((imgs[0] > 0) | (diff > 0))
    (y0, x0), (y1, x1) = lit.min(0), lit.max(0) + 1
    peak = float(imgs[0].max())
    fig, axes = plt.subplots(1, 3, figsize=(15, 5), sharex=True, sharey=True)
    titles = ("max_scatter 0", f"max_scatter {max_scatter}", "difference: interreflected light")
    for ax, img, title in zip(axes, (imgs[0], imgs[1], diff), titles):
        im = ax.imshow(np.log10(np.maximum(img[y0:y1, x0:x1], peak * 1e-5) / peak),
                       cmap="magma", vmin=-5, vmax=0, extent=(x0, x1, y1, y0))
        ax.set_title(title)
    fig.colorbar(im, ax=axes, label="log10 radiance / primary peak", shrink=0.8)
    fig.suptitle(f"{obj_name}: laser light in the paper rig ({spp} spp, scale {scale})")
    tmp = Path(path).with_name(f".{Path(path).stem}.tmp.png")
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    tmp.replace(path)
    return {"object": obj_name, "laser_sum": [float(imgs[0].sum()), float(imgs[1].sum())],
            "gain": float(imgs[1].sum() / imgs[0].sum() - 1.0),
            "secondary_peak_over_primary_peak": float(diff.max() / peak)}
