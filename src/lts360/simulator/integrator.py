"""A laser-triangulation integrator for Mitsuba 3: laser light through planar mirrors.

Why a custom integrator: the laser is a delta light (a sheet from a point apex) and the mirrors
are delta reflectors, so a path tracer can never connect laser → mirror → diffuse surface.
Planar mirrors make the *method of images* exact: the light that reaches a surface point ``x``
after the mirror sequence ``(a, b)`` (laser → a → b → x) comes from the virtual laser
``T_b T_a O``, and its irradiance is that of the real laser at the unfolded point
``x' = T_a T_b x`` (same path length, same sheet coordinates), provided the path crosses
every mirror inside its real rectangle, on its reflecting side, unoccluded.

Light paths simulated (L laser, S mirror, D any non-delta surface, E camera, A ambient):

* ``L (S){0..K} D (S){0..K} E`` — laser light reaching the surface directly or through up to
  ``K`` mirror reflections, seen directly or through up to ``K`` mirror reflections
  (camera-side mirror bounces are traced with the mirror BSDF; default ``K = 2``: the 90°
  corner's double reflections appear).  The surface response is Mitsuba's ``bsdf.eval``.
* ``A D (S){0..K} E`` — ambient light (constant environment) by emitter sampling, and
  ``A (S){0..K} E`` for camera rays that escape.

* ``L (S){0..K} D ((S){0..K} D){1..N} (S){0..K} E`` with ``N = max_scatter`` (0–3, default
  0) — interreflected laser light: laser light scattered by the object onto itself or onto a
  holder (``L D D E``), and glints carried by a mirror onto the object (``L D S D E``: the
  "multiple reflections" of paper §3.1 that arise from glossy surfaces).  Added camera-side:
  from the first non-delta point ``x₁`` the camera ray reaches, the BSDF is sampled
  (``bsdf.sample``: cosine-weighted for the diffuse lobe, GGX visible normals for the glossy
  one), the ray is followed through up to ``K`` mirrors to the next non-delta point ``x₂``,
  and the laser's direct light there (every virtual laser, the same visibility tests) times
  ``f(x₂; → laser, → x₁)`` is added with the path throughput ``f cosθ / pdf``; repeated
  ``N`` times.  With ``max_scatter = 0`` nothing of this runs (the image is bit-identical to
  the single-scatter integrator's).  The estimator's variance is discussed in
  ``docs/simulator.md``.

Not simulated: ambient light that is scattered more than once (it is shaded at ``x₁`` only),
ambient light reaching the object through a mirror, the laser aperture seen by the camera,
and subsurface scattering (the stripe in white PVC is slightly wider in reality).  Coherent
effects (speckle) are added in the sensor stage, not here.

Units: millimetres in the scene; the output is radiance in W m⁻² sr⁻¹ at the laser wavelength.
The laser-only radiance (direct and interreflected) is returned as the AOV ``laser`` so that
speckle can multiply only the coherent part.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from lts360.scenes.coverage import MAX_BOUNCES

__all__ = ["LaserParams", "MirrorParams", "check_max_scatter", "laser_params", "make_integrator",
           "MAX_SCATTER"]

#: The most interreflections of the laser light between non-delta surfaces.
MAX_SCATTER = 3

#: How far along a reflected ray its origin is put past the mirror (mm): far enough to clear the
#: mirror in float32 at ~100 mm coordinates (ulp ~8e-6 mm), on the exact reflected line.
MIRROR_STEP_MM = 1e-2

MM2_PER_M2 = 1.0e6
_SHADOW_EPS = 1e-4  # relative shortening of shadow segments (segments are 10–300 mm long)
#: Where a shadow ray restarts in front of a mirror it met (mm): clear of the mirror's shape in
#: float32 at ~100 mm coordinates.
SHADOW_CLEARANCE_MM = 1e-4
#: Normalisation of the Gaussian profile across the sheet: ∫ sqrt(2/π)/w exp(-2h²/w²) dh = 1.
_GAUSS_NORM = math.sqrt(2.0 / math.pi)
_GAUSS_CUT = 16.1  # exp(-16.1) = 1e-7


@dataclass(frozen=True)
class MirrorParams:
    """Plain-float description of a rectangular mirror for the integrator."""

    normal: tuple[float, float, float]
    d_mm: float
    center_mm: tuple[float, float, float]
    u_axis: tuple[float, float, float]
    v_axis: tuple[float, float, float]
    half_width_mm: float
    half_height_mm: float
    reflectance: float

    def reflect(self, p: np.ndarray) -> np.ndarray:
        n = np.asarray(self.normal)
        return p - 2.0 * (p @ n - self.d_mm) * n


@dataclass(frozen=True)
class LaserParams:
    """Plain-float description of the laser sheet for the integrator."""

    origin_mm: tuple[float, float, float]
    direction: tuple[float, float, float]
    normal: tuple[float, float, float]
    half_fan_rad: float
    fan_profile: str
    waist_mm: float
    waist_distance_mm: float
    rayleigh_range_mm: float
    power_W: float


def laser_params(rig, *, laser_on: bool = True, mirrors=None
                 ) -> tuple[LaserParams, tuple[MirrorParams, ...]]:
    """Extract the integrator's parameters from a :class:`lts360.scenes.rig.Rig`.

    ``mirrors`` (sequence of :class:`lts360.scenes.rig.Mirror`): the mirrors the laser light
    meets (method of images), if not the rig's own (the twin's laser side); default
    ``rig.mirrors``."""
    las = rig.laser
    lp = LaserParams(origin_mm=tuple(map(float, las.origin_mm)),
                     direction=tuple(map(float, las.direction)),
                     normal=tuple(map(float, las.normal)),
                     half_fan_rad=math.radians(las.fan_angle_deg) / 2.0,
                     fan_profile=las.fan_profile,
                     waist_mm=las.waist_um * 1e-3,
                     waist_distance_mm=float(las.waist_distance_mm),
                     rayleigh_range_mm=float(las.rayleigh_range_mm),
                     power_W=las.power_mW * 1e-3 if laser_on else 0.0)
    mps = tuple(MirrorParams(normal=tuple(map(float, m.normal)), d_mm=m.d_mm,
                             center_mm=tuple(map(float, m.center_mm)),
                             u_axis=tuple(map(float, m.u_axis)), v_axis=tuple(map(float, m.v_axis)),
                             half_width_mm=m.width_mm / 2.0, half_height_mm=m.height_mm / 2.0,
                             reflectance=float(m.reflectance))
                for m in (rig.mirrors if mirrors is None else mirrors))
    return lp, mps


def check_max_scatter(max_scatter) -> None:
    """``ValueError`` naming ``max_scatter`` and its range unless it is an integer in
    [0, :data:`MAX_SCATTER`]."""
    if isinstance(max_scatter, bool) or not isinstance(max_scatter, (int, np.integer)) \
            or not 0 <= max_scatter <= MAX_SCATTER:
        raise ValueError(f"max_scatter must be an integer in [0, {MAX_SCATTER}], got "
                         f"{max_scatter!r}")


def _sequences(n_mirrors: int, max_bounces: int) -> list[tuple[int, ...]]:
    from lts360.scenes.coverage import mirror_sequences

    return mirror_sequences(tuple(range(n_mirrors)), max_bounces)


@dataclass(frozen=True)
class _Setup:
    """What the integrator reads while it renders, fixed when it is built
    (:func:`make_integrator`'s parameters and what follows from them)."""

    laser: LaserParams
    mirrors: tuple[MirrorParams, ...]
    max_bounces: int
    ambient: bool
    clearance_mm: float
    max_scatter: int
    #: ``(sequence, virtual laser origin (mm), product of the mirrors' reflectances)``, one
    #: per mirror sequence the laser light can take (method of images).
    virtual: tuple[tuple[tuple[int, ...], tuple[float, float, float], float], ...]
    #: The sheet's in-plane axis normal to its direction (``normal × direction``).
    e2: tuple[float, float, float]
    #: Normalisation of the fan profile over its angle (1/rad).
    fan_norm: float
    #: A scalar Mitsuba variant (one sample at a time: Python bools for masks).
    scalar: bool


def _build_setup(laser: LaserParams, mirrors: tuple[MirrorParams, ...], *, max_bounces: int,
                 ambient: bool, clearance_mm: float, max_scatter: int, scalar: bool) -> _Setup:
    """The :class:`_Setup` of :func:`make_integrator`'s (checked) parameters."""
    O = np.asarray(laser.origin_mm)
    # Virtual lasers: light that met mirrors a then b appears to come from T_b T_a O.
    virtual = []
    for seq in _sequences(len(mirrors), max_bounces):
        p = O.copy()
        for k in seq:
            p = mirrors[k].reflect(p)
        refl = float(np.prod([mirrors[k].reflectance for k in seq])) if seq else 1.0
        virtual.append((seq, tuple(map(float, p)), refl))
    e2 = np.cross(np.asarray(laser.normal), np.asarray(laser.direction))
    half_fan = laser.half_fan_rad
    if laser.fan_profile == "flat":
        fan_norm = 1.0 / (2.0 * half_fan)
    else:  # Gaussian in angle, 1/e² at the fan edge
        fan_norm = 1.0 / (half_fan * math.sqrt(math.pi / 2.0))
    return _Setup(laser=laser, mirrors=tuple(mirrors), max_bounces=max_bounces, ambient=ambient,
                  clearance_mm=clearance_mm, max_scatter=max_scatter, virtual=tuple(virtual),
                  e2=tuple(map(float, e2)), fan_norm=fan_norm, scalar=scalar)


def make_integrator(laser: LaserParams, mirrors: tuple[MirrorParams, ...], *, max_bounces: int = 2,
                    ambient: bool = False, clearance_mm: float = SHADOW_CLEARANCE_MM,
                    max_scatter: int = 0):
    """Build the integrator (the Mitsuba variant must already be set).

    Parameters
    ----------
    laser : LaserParams
    mirrors : tuple of MirrorParams
        The mirrors the laser light meets.  Their planes should match the mirror shapes in
        the scene; where they do not (the twin's laser-side mirrors, turned by a few 0.01°
        about their line in the sheet), ``clearance_mm`` must exceed how far a shape lies
        in front of its plane where the light meets it.
    max_bounces : int, [0, 3]
        Longest mirror sequence on the camera side and on the laser side.
    ambient : bool
        Whether to sample the scene's emitters (ambient light).
    clearance_mm : float, > 0
        How far in front of a mirror's plane a shadow ray restarts after it (the mirror's own
        shape must not occlude it).
    max_scatter : int, [0, 3]
        Interreflections of the laser light between non-delta surfaces (``0``: none, the
        single-scatter image bit for bit).
    """
    import drjit as dr
    import mitsuba as mi

    if not 0 <= max_bounces <= MAX_BOUNCES:
        raise ValueError(f"max_bounces must be in [0, {MAX_BOUNCES}], got {max_bounces}")
    if not 0 < clearance_mm <= 1.0:
        raise ValueError(f"clearance_mm must be in (0, 1], got {clearance_mm}")
    check_max_scatter(max_scatter)
    setup = _build_setup(laser, mirrors, max_bounces=max_bounces, ambient=ambient,
                         clearance_mm=clearance_mm, max_scatter=max_scatter,
                         scalar=not dr.is_array_v(mi.Float))
    return _integrator_class(mi.variant())(setup)


@functools.lru_cache(maxsize=None)
def _integrator_class(variant: str):
    """The integrator class of the Mitsuba ``variant`` (the one set now: its base class
    ``mi.SamplingIntegrator`` exists only once a variant is set), made once per variant.
    The class only delegates to the module's functions, which read the :class:`_Setup`."""
    import mitsuba as mi

    class LaserTriangulationIntegrator(mi.SamplingIntegrator):
        def __init__(self, setup: _Setup, props=None):
            super().__init__(props if props is not None else mi.Properties())
            self.setup = setup

        def aov_names(self):
            return ["laser"]

        def to_string(self):
            s = self.setup
            return (f"LaserTriangulationIntegrator[max_bounces={s.max_bounces}, "
                    f"max_scatter={s.max_scatter}, paths={len(s.virtual)}]")

        def sample(self, scene, sampler, ray, medium=None, active=True):
            return _sample(self.setup, scene, sampler, ray, active)

    return LaserTriangulationIntegrator


# The integrator's methods, as functions of its setup.  Each runs in the variant that is set
# (in a JIT variant once, while Dr.Jit traces the kernel; in a scalar one per sample).

def _vec(v):
    import mitsuba as mi

    return mi.Vector3f(float(v[0]), float(v[1]), float(v[2]))


def _point(v):
    import mitsuba as mi

    return mi.Point3f(float(v[0]), float(v[1]), float(v[2]))


def _reflect_point(p, m: MirrorParams):
    import drjit as dr

    n = _vec(m.normal)
    return p - 2.0 * (dr.dot(p, n) - m.d_mm) * n


def _not(mask):
    """``~mask``; for a Python bool (scalar variants) ``~`` is an int, not a negation."""
    return (not mask) if isinstance(mask, bool) else ~mask


def _irradiance_perp(s: _Setup, xp):
    """Irradiance (W/mm²) on a plane normal to the beam at unfolded points ``xp``."""
    import drjit as dr

    laser = s.laser
    half_fan = laser.half_fan_rad
    u = xp - _point(laser.origin_mm)
    h = dr.dot(u, _vec(laser.normal))
    up = u - h * _vec(laser.normal)
    rho = dr.norm(up)
    phi = dr.atan2(dr.dot(up, _vec(s.e2)), dr.dot(up, _vec(laser.direction)))
    if laser.fan_profile == "flat":
        fan = dr.select(dr.abs(phi) <= half_fan, s.fan_norm, 0.0)
    else:
        fan = s.fan_norm * dr.exp(-2.0 * dr.square(phi / half_fan))
    w = laser.waist_mm * dr.sqrt(1.0 + dr.square((rho - laser.waist_distance_mm)
                                                  / laser.rayleigh_range_mm))
    q = 2.0 * dr.square(h / w)
    # Truncate the Gaussian at 1e-7 of its peak (|h| > 2.84 w): no visible light is
    # lost and the shadow rays of the far tails are skipped.
    across = dr.select(q < _GAUSS_CUT, _GAUSS_NORM / w * dr.exp(-q), 0.0)
    return laser.power_W * fan / dr.maximum(rho, 1e-6) * across, rho


def _shadow_ray(si, p, end, first: bool):
    """The shadow ray from ``p`` to ``end`` (from the surface point ``si`` if ``first``),
    shortened by the relative ``_SHADOW_EPS``."""
    import drjit as dr
    import mitsuba as mi

    if first:
        ray = si.spawn_ray_to(end)
    else:
        ray = mi.Ray3f(p, dr.normalize(end - p))
        ray.maxt = dr.norm(end - p)
    ray.maxt = ray.maxt * (1.0 - _SHADOW_EPS)
    return ray


def _visible(s: _Setup, scene, si, seq, O_v, active):
    """Shadow test of the path x → (mirrors, reversed) → laser."""
    import drjit as dr
    import mitsuba as mi

    vis = mi.Bool(active)
    p = mi.Point3f(si.p)
    target = _point(O_v)
    first = True
    for k in reversed(seq):
        m = s.mirrors[k]
        n = _vec(m.normal)
        seg = target - p
        dn = dr.dot(seg, n)
        side = dr.dot(p, n) - m.d_mm
        t = -side / dr.select(dn != 0, dn, 1.0)
        vis = vis & (side > 0) & (dn < 0) & (t > 0) & (t < 1)
        hit = p + t * seg
        q = hit - _point(m.center_mm)
        vis = vis & (dr.abs(dr.dot(q, _vec(m.u_axis))) <= m.half_width_mm) \
                  & (dr.abs(dr.dot(q, _vec(m.v_axis))) <= m.half_height_mm)
        hit_off = hit + n * s.clearance_mm  # just in front of the mirror surface
        vis = vis & _not(scene.ray_test(_shadow_ray(si, p, hit_off, first), vis))
        target = _reflect_point(target, m)
        p = hit_off
        first = False
    ray = _shadow_ray(si, p, _point(s.laser.origin_mm), first)
    return vis & _not(scene.ray_test(ray, vis))


def _laser(s: _Setup, scene, si, bsdf, active):
    """The laser's direct light (every virtual laser) scattered at ``si`` towards ``si.wi``."""
    import drjit as dr
    import mitsuba as mi

    ctx = mi.BSDFContext()
    out = mi.Spectrum(0.0)
    if s.laser.power_W == 0.0:
        return out
    for seq, O_v, refl in s.virtual:
        # Unfolded point x' = T_first ... T_last x (apply the last mirror first).
        xp = mi.Point3f(si.p)
        for k in reversed(seq):
            xp = _reflect_point(xp, s.mirrors[k])
        E_perp, _ = _irradiance_perp(s, xp)
        lit = active & (E_perp > 0)
        to_l = _point(O_v) - si.p
        wi_world = dr.normalize(to_l)
        lit = lit & (dr.dot(wi_world, si.n) > 0)
        lit = _visible(s, scene, si, seq, O_v, lit)
        f = bsdf.eval(ctx, si, si.to_local(wi_world), lit)
        out += dr.select(lit, f * (E_perp * refl * MM2_PER_M2), 0.0)
    return out


def _to_surface(s: _Setup, scene, sampler, ray, active, beta, env=None):
    """Follow ``ray`` through up to ``max_bounces`` mirror reflections to the first
    non-delta surface.  Returns ``(ray, found, beta, L_env)``: the last ray (from the
    last mirror, or the original), whether it meets a non-delta surface, the
    throughput times the mirrors' weights, and the environment light of rays that
    escape (``env``: the ambient emitter, or None)."""
    import drjit as dr
    import mitsuba as mi

    ctx = mi.BSDFContext()
    L = mi.Spectrum(0.0)
    found = mi.Bool(False)
    si_found = None
    for depth in range(s.max_bounces + 1):
        si = scene.ray_intersect(ray, active)
        valid = active & si.is_valid()
        if env is not None:
            L += dr.select(active & _not(si.is_valid()), beta * env.eval(si, active), 0.0)
        if s.scalar and not valid:  # a scalar miss has no BSDF to ask for its flags
            break
        bsdf = si.bsdf(ray)
        is_mirror = valid & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
        hit = valid & _not(is_mirror)
        if not s.scalar:  # the surface met, kept (the shading needs no second intersection)
            si_found = si if si_found is None else dr.select(hit, si, si_found)
        found = found | hit
        if depth == s.max_bounces:
            break
        bs, w = bsdf.sample(ctx, si, sampler.next_1d(is_mirror), sampler.next_2d(is_mirror),
                            is_mirror)
        beta = dr.select(is_mirror, beta * w, beta)
        # Start the reflected ray on the exact reflected line, a little way along it:
        # `spawn_ray` offsets the origin along the mirror normal (~7 µm at these
        # coordinates), which displaced every mirror view by ~2.5 µm in the section.
        wo = si.to_world(bs.wo)
        ray = dr.select(is_mirror, mi.Ray3f(si.p + wo * MIRROR_STEP_MM, wo, si.time,
                                            si.wavelengths), ray)
        active = is_mirror & (bs.pdf > 0)
    return ray, found, beta, L, si_found


def _sample(s: _Setup, scene, sampler, ray, active):
    """``SamplingIntegrator.sample``: ``(radiance, valid, [laser radiance])`` of a camera ray."""
    import drjit as dr
    import mitsuba as mi

    # 1. Follow the camera ray through up to K mirror reflections until it meets a
    #    non-delta surface (escaped rays see the ambient environment).
    ctx = mi.BSDFContext()
    env = scene.environment() if s.ambient else None
    ray, found, throughput, L, si = _to_surface(s, scene, sampler, mi.Ray3f(ray),
                                                mi.Bool(active), mi.Spectrum(1.0), env)
    # 2. Shade once at that surface: the laser through every mirror sequence (method of
    #    images) and the ambient light by emitter sampling.
    if s.scalar and not found:
        return L, mi.Bool(True), [mi.Float(0.0)]
    if si is None:  # a scalar variant: intersect again
        si = scene.ray_intersect(ray, found)
    found = found & si.is_valid()
    bsdf = si.bsdf(ray)
    L_laser = throughput * _laser(s, scene, si, bsdf, found)
    L += L_laser
    if s.ambient:
        ds, em_w = scene.sample_emitter_direction(si, sampler.next_2d(found), True, found)
        f = bsdf.eval(ctx, si, si.to_local(ds.d), found)
        L += dr.select(found & (ds.pdf > 0), throughput * f * em_w, 0.0)
    if s.max_scatter > 0 and s.laser.power_W != 0.0:
        L_scatter = _scatter(s, scene, sampler, si, bsdf, throughput, found)
        L_laser = L_laser + L_scatter
        L = L + L_scatter
    aov = L_laser[0] if mi.is_monochromatic else mi.luminance(L_laser)
    return L, mi.Bool(True), [aov]


def _scatter(s: _Setup, scene, sampler, si, bsdf, throughput, active):
    """Interreflected laser light seen at ``si`` (``max_scatter`` BSDF-sampled bounces)."""
    import drjit as dr
    import mitsuba as mi

    ctx = mi.BSDFContext()
    out = mi.Spectrum(0.0)
    beta = mi.Spectrum(throughput)
    active = mi.Bool(active)
    for _ in range(s.max_scatter):
        if s.scalar and not active:
            break
        bs, w = bsdf.sample(ctx, si, sampler.next_1d(active), sampler.next_2d(active), active)
        beta = beta * w
        active = active & (bs.pdf > 0)
        ray = si.spawn_ray(si.to_world(bs.wo))
        # Through up to K mirrors to the next non-delta point (as the camera ray).
        ray, found, beta, _, _ = _to_surface(s, scene, sampler, ray, active, beta)
        if s.scalar and not found:
            break
        si = scene.ray_intersect(ray, found)
        active = found & si.is_valid()
        bsdf = si.bsdf(ray)
        out += dr.select(active, beta * _laser(s, scene, si, bsdf, active), 0.0)
    return out
