"""Mitsuba emitter plugin ``laser_sheet``: the laser sheet as a light Mitsuba's own integrators use.

A yardstick, not the simulator's light: Mitsuba's ``path`` integrator cannot connect a delta
sheet through a mirror, but in a scene without mirrors it renders the sheet's light directly
and scattered any number of times (``max_depth``), with its own sampling, visibility and MIS.
Comparing its images with the laser integrator's (:mod:`lts360.simulator.integrator`) checks
the latter's interreflected light (``max_scatter``) by an independent light-transport code.

The emitter is a delta-position light at the sheet's apex.  For a receiving point ``x`` it
returns the irradiance on a plane normal to the beam, written here anew from the sheet model
(not shared with the integrator, so that the comparison also checks the sheet's formulas): the
fan profile over the in-plane angle ``φ`` (flat, or Gaussian with 1/e² at the fan edge) divided
by the in-plane distance ``ρ``, times the normalised Gaussian across the sheet of width
``w(ρ) = w₀ √(1 + ((ρ − ρ_w)/z_R)²)`` at the distance ``h`` from the sheet's plane, times the
power; W/mm² converted to W/m² (radiance in W m⁻² sr⁻¹ once a BSDF multiplies it).
"""

from __future__ import annotations

import math

__all__ = ["PLUGIN_NAME", "register", "sheet_emitter_dict"]

PLUGIN_NAME = "laser_sheet"
_registered: set[str] = set()


def sheet_emitter_dict(laser) -> dict:
    """Mitsuba dictionary of the sheet of a :class:`~lts360.simulator.integrator.LaserParams`."""
    return {"type": PLUGIN_NAME,
            "origin": ",".join(map(repr, map(float, laser.origin_mm))),
            "direction": ",".join(map(repr, map(float, laser.direction))),
            "normal": ",".join(map(repr, map(float, laser.normal))),
            "half_fan_rad": float(laser.half_fan_rad), "fan_profile": str(laser.fan_profile),
            "waist_mm": float(laser.waist_mm), "waist_distance_mm": float(laser.waist_distance_mm),
            "rayleigh_range_mm": float(laser.rayleigh_range_mm), "power_W": float(laser.power_W)}


def _emitter_class():
    import drjit as dr
    import mitsuba as mi

    def vec(props, key):
        return tuple(float(c) for c in props.get(key).split(","))

    class LaserSheetEmitter(mi.Emitter):
        def __init__(self, props):
            super().__init__(props)
            self.m_flags = mi.EmitterFlags.DeltaPosition
            self.o = vec(props, "origin")
            self.d = vec(props, "direction")
            self.n = vec(props, "normal")
            n, d = (dr.scalar.Array3f(*v) for v in (self.n, self.d))
            self.e2 = tuple(float(c) for c in dr.cross(n, d))
            self.half_fan = props.get("half_fan_rad")
            self.profile = props.get("fan_profile")
            if self.profile not in ("flat", "gaussian"):
                raise ValueError(f"laser_sheet: fan_profile must be flat or gaussian, got {self.profile!r}")
            self.w0 = props.get("waist_mm")
            self.rho_w = props.get("waist_distance_mm")
            self.z_r = props.get("rayleigh_range_mm")
            self.power = props.get("power_W")

        def _irradiance(self, p):
            rel = p - mi.Point3f(*self.o)
            h = dr.dot(rel, mi.Vector3f(*self.n))
            x = dr.dot(rel, mi.Vector3f(*self.d))
            y = dr.dot(rel, mi.Vector3f(*self.e2))
            rho = dr.sqrt(x * x + y * y)
            phi = dr.atan2(y, x)
            if self.profile == "flat":
                fan = dr.select(dr.abs(phi) <= self.half_fan, 0.5 / self.half_fan, 0.0)
            else:
                fan = dr.exp(-2.0 * dr.square(phi / self.half_fan)) / (
                    self.half_fan * math.sqrt(math.pi / 2.0))
            w = self.w0 * dr.sqrt(1.0 + dr.square((rho - self.rho_w) / self.z_r))
            across = math.sqrt(2.0 / math.pi) / w * dr.exp(-2.0 * dr.square(h / w))
            return self.power * fan / dr.maximum(rho, 1e-6) * across * 1.0e6

        def sample_direction(self, it, sample, active=True):
            ds = dr.zeros(mi.DirectionSample3f)
            o = mi.Point3f(*self.o)
            to_o = o - it.p
            dist = dr.norm(to_o)
            ds.p = o
            ds.d = to_o / dist
            ds.n = -ds.d
            ds.dist = dist
            ds.pdf = 1.0
            ds.delta = True
            ds.time = it.time
            ds.emitter = mi.EmitterPtr(self)
            return ds, mi.Spectrum(dr.select(active, self._irradiance(it.p), 0.0))

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Spectrum(dr.select(active, self._irradiance(it.p), 0.0))

        def eval(self, si, active=True):
            return mi.Spectrum(0.0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"LaserSheetEmitter[origin={self.o}, power_W={self.power}]"

    return LaserSheetEmitter


def register() -> None:
    """Register ``laser_sheet`` for the active variant (idempotent; set the variant first)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("no Mitsuba variant is set: call mitsuba.set_variant(...) first")
    if variant in _registered:
        return
    cls = _emitter_class()
    mi.register_emitter(PLUGIN_NAME, lambda props: cls(props))
    _registered.add(variant)
