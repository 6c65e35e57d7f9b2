"""Turn :class:`lts360.scenes.materials.Material` into Mitsuba BSDF dictionaries."""

from __future__ import annotations

from lts360.scenes.materials import Material

__all__ = ["material_to_bsdf", "mirror_bsdf"]


def _spectrum(value: float) -> dict:
    return {"type": "spectrum", "value": float(value)}


def material_to_bsdf(material: Material) -> dict:
    """``blendbsdf``: ``(1 - w) · diffuse(ρ) + w · roughconductor(GGX α, η + iκ)``."""
    diffuse = {"type": "diffuse", "reflectance": _spectrum(material.diffuse_reflectance)}
    if material.specular_weight == 0.0:
        return diffuse
    conductor = {"type": "roughconductor", "distribution": "ggx", "alpha": float(material.roughness_alpha),
                 "eta": _spectrum(material.eta), "k": _spectrum(max(material.k, 1e-6))}
    return {"type": "blendbsdf", "weight": float(material.specular_weight),
            "bsdf_0": diffuse, "bsdf_1": conductor}


def mirror_bsdf(reflectance: float) -> dict:
    """First-surface mirror: a smooth conductor of the given specular reflectance (one-sided;
    the back is black)."""
    return {"type": "conductor", "material": "none", "specular_reflectance": _spectrum(reflectance)}
