"""Surface materials of the objects, as seen by a 660 nm laser.

Each material is a mixture of a Lambertian lobe and a rough (GGX) conductor lobe:
``f = (1 - w) · diffuse + w · conductor``.  The simulator turns it into a Mitsuba
``blendbsdf``; nothing here imports Mitsuba.  Complex refractive indices are the usual
handbook values at 650–660 nm (Rakić 1995 for Al, Johnson & Christy 1974 for Fe/Cu–Zn
approximated); they set the Fresnel reflectance of the specular lobe.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Material", "MATERIALS", "get_material", "SHINY_SPECULAR_WEIGHT",
           "auto_max_scatter", "resolve_max_scatter"]


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


#: A material whose glossy lobe carries at least this share of the blend is *shiny*: its laser
#: light scattered onto the object itself changes what is measured (STUDIES.md,
#: "Interreflections"). Measured on the examples with one bounce against none (same seeds):
#: brass (0.65) and polished aluminium (0.90) lose or gain tens of points off by > 0.2 mm and
#: 10–20° of coverage, machined aluminium (0.55) reads up to 1 mm outliers on a full scan;
#: ground steel (0.45: the plug gauge, −0.6 µm on the mean radius), weathered aluminium
#: (0.25: the cables, no consistent change), black oxide, rust and PVC change within the
#: render noise.
SHINY_SPECULAR_WEIGHT = 0.5


def auto_max_scatter(material: Material) -> int:
    """The interreflection bounces ``--max-scatter auto`` renders for an object of
    ``material``: 1 where it is shiny (specular weight >= :data:`SHINY_SPECULAR_WEIGHT`),
    else 0 (its images stay the single-scatter ones, bit for bit)."""
    return 1 if material.specular_weight >= SHINY_SPECULAR_WEIGHT else 0


def resolve_max_scatter(value, material: Material) -> int:
    """``value`` (an int 0–3, or ``"auto"``) as the bounces to render for ``material``."""
    if isinstance(value, str):
        if value == "auto":
            return auto_max_scatter(material)
        try:
            value = int(value)
        except ValueError:
            raise ValueError(f"max_scatter must be 'auto' or 0-3, got {value!r}") from None
    if isinstance(value, bool) or int(value) != value or not 0 <= int(value) <= 3:
        raise ValueError(f"max_scatter must be 'auto' or 0-3, got {value!r}")
    return int(value)
