"""Everything measured on one section: centre, diameters, ovality, roundness against the four
reference circles, harmonics, coverage and gaps.

Every quantity is computed on the binned profile about the LS centre
(:func:`lts360.inspect.profile.bin_profile`: 0.5° bins, each direction counted once where views
overlap), the LS circle included.  The scatter ``σ`` of the points about
their bin's mean (views included) feeds the uncertainty (:mod:`lts360.inspect.uncertainty`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lts360.inspect.circles import (
    ReferenceCircle,
    inscribed_on_a_chord,
    least_squares_circle,
    reference_circles,
)
from lts360.inspect.diameters import Diameters, diameters
from lts360.inspect.harmonics import DEFAULT_MAX_ORDER, Harmonics, fit_harmonics
from lts360.inspect.profile import (
    DEFAULT_BIN_DEG,
    DEFAULT_GAP_DEG,
    BinnedProfile,
    Gap,
    bin_profile,
    coverage_deg,
    gaps,
    gaussian_filter,
    interp_profile,
    uniform_profile,
)

__all__ = ["SectionResult", "analyse_section", "MIN_POINTS"]

#: Fewest valid points a section needs to be inspected (a circle and a few lobes).
MIN_POINTS = 12
#: A gap wider than this (deg) is named in the section's warnings.
WIDE_GAP_DEG = 30.0


@dataclass(frozen=True, eq=False)
class SectionResult:
    """One inspected section (mm, deg).

    Attributes
    ----------
    index : int
        The cloud's section number.
    z_mm : float
        Stage position.
    n_valid, n_samples : int
        Valid points and every θ sample of the section.
    coverage_deg : float
    gaps : list of Gap
    circles : dict name → ReferenceCircle
    diameters : Diameters
    harmonics : Harmonics
    scatter_mm : float
        Standard deviation of one point about its bin's mean.
    points_per_bin : float
        Mean number of points in a bin.
    profile : BinnedProfile
    xy_mm : (n, 2) float
        The valid points.
    """

    index: int
    z_mm: float
    n_valid: int
    n_samples: int
    coverage_deg: float
    gaps: list[Gap]
    circles: dict[str, ReferenceCircle]
    diameters: Diameters
    harmonics: Harmonics
    scatter_mm: float
    points_per_bin: float
    profile: BinnedProfile
    xy_mm: np.ndarray
    extra: dict = field(default_factory=dict)

    @property
    def ls(self) -> ReferenceCircle:
        return self.circles["LSCI"]


def _scatter(xy: np.ndarray, profile: BinnedProfile) -> tuple[float, float]:
    """σ of one point about the binned profile interpolated at its θ (the profile's own slope
    and the bins' averaging removed), and the mean points per bin."""
    d = xy - profile.centre_mm
    res = np.hypot(d[:, 0], d[:, 1]) - interp_profile(profile, np.arctan2(d[:, 1], d[:, 0]),
                                                      gap_deg=360.0)
    dof = len(res) - len(profile.r_mm)
    sigma = float(np.sqrt(res @ res / dof)) if dof > 0 else float("nan")
    return sigma, float(np.mean(profile.count))


def analyse_section(xy_mm, *, index: int = 0, z_mm: float = 0.0, theta_invalid_rad=None,
                    quality_invalid=None, theta_valid_rad=None,
                    bin_deg: float = DEFAULT_BIN_DEG, gap_deg: float = DEFAULT_GAP_DEG,
                    filter_upr: float | None = None) -> SectionResult:
    """Inspect one section.

    Parameters
    ----------
    xy_mm : (n, 2) float
        Its valid points in the measurement frame.
    theta_valid_rad : (n,) float, optional
        Their θ as measured (about the measurement axis; default: computed from ``xy_mm``):
        coverage and gaps are counted in these.
    theta_invalid_rad, quality_invalid : (m,) float, (m,) int, optional
        The section's invalid samples (named in the gaps).
    filter_upr : float, optional
        Pass the profile through the ISO 12181-2 Gaussian filter with this cut-off before the
        reference circles and diameters (:func:`lts360.inspect.profile.gaussian_filter`); the
        harmonics and the scatter stay those of the unfiltered profile.

    Raises
    ------
    ValueError
        Fewer than :data:`MIN_POINTS` valid points.
    """
    xy = np.asarray(xy_mm, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"xy_mm must have shape (n, 2), got {xy.shape}")
    if len(xy) < MIN_POINTS:
        raise ValueError(f"section {index} (z = {z_mm:g} mm): {len(xy)} valid points, at least "
                         f"{MIN_POINTS} needed")
    th_meas = np.arctan2(xy[:, 1], xy[:, 0]) if theta_valid_rad is None else theta_valid_rad
    # The LS circle of the binned profile: each direction weighs the same however many views
    # saw it (on a non-round section the plain LS circle of the points moves with the
    # sampling).  Binned about the LS centre of the points, fitted, binned again.
    prof = bin_profile(xy, least_squares_circle(xy).centre_mm, bin_deg=bin_deg)
    if len(prof.r_mm) >= MIN_POINTS:
        prof = bin_profile(xy, least_squares_circle(prof.xy_mm).centre_mm, bin_deg=bin_deg)
    raw = prof
    if filter_upr is not None and len(prof.r_mm) >= MIN_POINTS:
        prof = gaussian_filter(prof, filter_upr, gap_deg=gap_deg)
    pxy = prof.xy_mm if len(prof.r_mm) >= MIN_POINTS else xy
    circles = reference_circles(pxy)
    sigma, per_bin = _scatter(xy, raw)
    th_u, r_u = uniform_profile(raw, gap_deg=gap_deg)
    gap_list = gaps(th_meas, theta_invalid_rad=theta_invalid_rad,
                    quality_invalid=quality_invalid, gap_deg=gap_deg)
    widest = max((g.width_deg for g in gap_list), default=0.0)
    # a gap wider than half a period leaves that order undetermined: fit fewer orders
    k_max = DEFAULT_MAX_ORDER if widest == 0 else int(np.clip(180.0 / widest, 2,
                                                              DEFAULT_MAX_ORDER))
    harm = (fit_harmonics(th_u, r_u, max_order=k_max) if np.all(np.isfinite(r_u))
            else fit_harmonics(raw.theta_rad, raw.r_mm, max_order=k_max))
    warnings = []
    if widest > WIDE_GAP_DEG:
        warnings.append(f"a gap of {widest:.0f}°: the MCCI, MICI, two-point diameters across it "
                        f"and harmonics above order {k_max} are not determined by the points")
    chord = inscribed_on_a_chord(pxy, circles["MICI"])
    if chord > 0:
        warnings.append(f"the MICI rests on the chord across a gap of {chord:.1f}°: not "
                        f"determined by the points (its RONt and diameter are not reported)")
    n_inv = 0 if quality_invalid is None else len(quality_invalid)
    return SectionResult(
        index=int(index), z_mm=float(z_mm), n_valid=len(xy), n_samples=len(xy) + n_inv,
        coverage_deg=coverage_deg(th_meas, gap_deg=gap_deg),
        gaps=gap_list,
        circles=circles, diameters=diameters(prof, gap_deg=gap_deg),
        harmonics=harm, scatter_mm=sigma,
        points_per_bin=per_bin, profile=prof, xy_mm=xy,
        extra={"warnings": warnings, "raw_profile": raw,
               "undetermined": ["MICI"] if chord > 0 else []})
