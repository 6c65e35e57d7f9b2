"""Surface materials of the objects, as seen by a 660 nm laser.

Each material is a mixture of a Lambertian lobe and a rough (GGX) conductor lobe:
``f = (1 - w) · diffuse + w · conductor``.  The simulator turns it into a Mitsuba
``blendbsdf``; nothing here imports Mitsuba.  Complex refractive indices are the usual
handbook values at 650–660 nm (Rakić 1995 for Al, Johnson & Christy 1974 for Fe/Cu–Zn
approximated); they set the Fresnel reflectance of the specular lobe.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Material", "MATERIALS", "get_material"]


@dataclass(frozen=True)
class Material:
    """A two-lobe surface model at the laser wavelength.

    Attributes
    ----------
    name : str
    diffuse_reflectance : float, [0, 1]
        Albedo of the Lambertian lobe.
    specular_weight : float, [0, 1]
        Weight ``w`` of the rough-conductor lobe in the blend.
    roughness_alpha : float, (0, 1]
        GGX roughness of the conductor lobe.
    eta, k : float, >0 and >=0
        Complex refractive index ``eta + i k`` of the conductor lobe.
    """

    name: str
    diffuse_reflectance: float
    specular_weight: float
    roughness_alpha: float
    eta: float
    k: float

    def __post_init__(self) -> None:
        for field, lo, hi in (("diffuse_reflectance", 0.0, 1.0), ("specular_weight", 0.0, 1.0),
                              ("roughness_alpha", 1e-4, 1.0)):
            value = getattr(self, field)
            if not (lo <= value <= hi):
                raise ValueError(f"material {self.name}: {field} must be in [{lo}, {hi}], got {value}")
        if self.eta <= 0 or self.k < 0:
            raise ValueError(f"material {self.name}: eta must be > 0 and k >= 0, got {self.eta}, {self.k}")


MATERIALS: dict[str, Material] = {m.name: m for m in (
    # Matte white PVC: strong volume (Lambertian) scattering, a weak glossy surface reflection.
    Material("white-pvc", diffuse_reflectance=0.80, specular_weight=0.04, roughness_alpha=0.30,
             eta=1.54, k=0.0),
    # Ground / lapped tool steel of a plug gauge: mostly glossy, some diffuse scattering.
    Material("ground-steel", diffuse_reflectance=0.35, specular_weight=0.45, roughness_alpha=0.15,
             eta=2.93, k=2.97),
    # Machined (turned) aluminium: bright, glossy.
    Material("machined-aluminium", diffuse_reflectance=0.30, specular_weight=0.55,
             roughness_alpha=0.12, eta=1.49, k=7.82),
    # Weathered aluminium strands of a distribution cable: greyer, rougher.
    Material("weathered-aluminium", diffuse_reflectance=0.45, specular_weight=0.25,
             roughness_alpha=0.25, eta=1.49, k=7.82),
    # Black-oxide steel: dark, slightly glossy.
    Material("black-oxide-steel", diffuse_reflectance=0.05, specular_weight=0.15,
             roughness_alpha=0.20, eta=2.93, k=2.97),
    # Rust (iron oxides): rough, reddish-brown, no specular lobe to speak of at 660 nm.
    Material("rust", diffuse_reflectance=0.30, specular_weight=0.02, roughness_alpha=0.6,
             eta=2.9, k=0.1),
    # Brass: glossy, warm; the conductor lobe dominates.
    Material("brass", diffuse_reflectance=0.15, specular_weight=0.65, roughness_alpha=0.10,
             eta=0.44, k=3.60),
    # Polished (lapped, mirror-like) aluminium: almost all conductor lobe, a narrow one; the
    # diffuse share (1 - w)·ρ = 0.02 stands for the residual haze of polishing marks.
    Material("polished-aluminium", diffuse_reflectance=0.20, specular_weight=0.90,
             roughness_alpha=0.04, eta=1.49, k=7.82),
    # Glossy black plastic (ABS/PMMA-like): a dielectric coat, Fresnel 4-5 % at normal
    # incidence (n = 1.5; a conductor lobe with k = 0 reflects as a dielectric), over a black
    # body (diffuse share (1 - w)·ρ = 0.03).
    Material("glossy-black-plastic", diffuse_reflectance=0.30, specular_weight=0.90,
             roughness_alpha=0.08, eta=1.50, k=0.0),
)}


def get_material(name: str) -> Material:
    """Material preset by name; ``ValueError`` lists the valid names."""
    try:
        return MATERIALS[name]
    except KeyError:
        raise ValueError(f"unknown material {name!r}; choose one of {', '.join(MATERIALS)}") from None
