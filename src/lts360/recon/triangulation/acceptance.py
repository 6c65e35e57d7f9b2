"""Is a measured section a measurement?  Coverage against what the views predict.

Every θ of the grid that lies in some view's window is a θ the calibrated rig should measure
(the windows come from the calibration's geometry, :mod:`lts360.recon.triangulation.views`).
The cloud of :func:`lts360.recon.triangulation.measure.result_to_cloud` holds one row per view
and windowed θ, valid (finite) or not, so both the predicted and the measured coverage of each
section follow from the cloud alone.  A section that measures less than a stated fraction of
its predicted coverage — none at all when its band misses the object — is refused, with one
line that names the views searched, the radii and what to try.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.recon.triangulation.cloud import VIEW_CODES, Cloud
from lts360.recon.triangulation.grid import CylGrid

__all__ = ["SectionCoverage", "section_coverage", "refusal", "DEFAULT_MIN_COVERAGE"]

#: Share of the predicted coverage a section must measure to be accepted.
DEFAULT_MIN_COVERAGE = 0.5

_VIEW_NAMES = {code: name for name, code in VIEW_CODES.items()}


@dataclass(frozen=True)
class SectionCoverage:
    """One section's coverage.

    Attributes
    ----------
    section : int
    n_valid : int
        Valid points (every view).
    predicted_deg : float or None
        θ inside some view's window × the grid step; ``None`` when the cloud holds only its
        valid points (the classic method), which says nothing of what was searched.
    measured_deg : float
        θ with at least one valid point × the grid step.
    views : tuple of str
        The views that searched this section.
    """

    section: int
    n_valid: int
    predicted_deg: float | None
    measured_deg: float
    views: tuple[str, ...]

    @property
    def fraction(self) -> float | None:
        """Measured over predicted coverage (``None`` when nothing was predicted)."""
        if not self.predicted_deg:
            return None
        return self.measured_deg / self.predicted_deg


def section_coverage(cloud: Cloud, grid: CylGrid, *, n_sections: int,
                     windows_in_cloud: bool = True) -> list[SectionCoverage]:
    """Coverage of sections ``0 .. n_sections - 1`` of ``cloud`` measured on ``grid``.

    ``windows_in_cloud``: the cloud has a row for every windowed θ of every view (inverse
    triangulation); ``False`` for a cloud of valid points only (classic), whose predicted
    coverage is then unknown.
    """
    step_deg = float(np.degrees(grid.theta_step_rad))
    k = np.rint((np.asarray(cloud.theta_rad) - grid.theta_rad[0]) / grid.theta_step_rad).astype(np.int64)
    if grid.is_full_turn:
        k = np.mod(k, grid.n_theta)
    sec = np.asarray(cloud.section, dtype=np.int64)
    valid = np.isfinite(cloud.radius_mm)

    def per_section(mask: np.ndarray, distinct: bool) -> np.ndarray:
        s = sec[mask]
        if distinct and s.size:
            s = np.unique(np.column_stack([s, k[mask]]), axis=0)[:, 0]
        return np.bincount(s, minlength=n_sections)[:n_sections]

    searched = per_section(np.ones(len(sec), bool), distinct=False)
    pred = per_section(np.ones(len(sec), bool), distinct=True)
    meas = per_section(valid, distinct=True)
    n_valid = per_section(valid, distinct=False)
    out = []
    for s in range(n_sections):
        codes = np.unique(cloud.view[sec == s]) if searched[s] else np.array([], np.uint8)
        out.append(SectionCoverage(
            section=s, n_valid=int(n_valid[s]),
            predicted_deg=float(pred[s] * step_deg) if windows_in_cloud else None,
            measured_deg=float(meas[s] * step_deg),
            views=tuple(_VIEW_NAMES.get(int(c), f"view {int(c)}") for c in codes)))
    return out


def refusal(coverages: list[SectionCoverage], grid: CylGrid, *,
            min_fraction: float = DEFAULT_MIN_COVERAGE, views: tuple[str, ...] = (),
            searched_band: str | None = None) -> str | None:
    """One line saying why the measurement is refused, or ``None`` when every section passes.

    A section fails with no valid point, or with less than ``min_fraction`` of its predicted
    coverage.  ``views``: the views the plan searched (named when a section has no rows).
    ``searched_band``: the radii searched, in words, when the band was found from the image
    (:meth:`lts360.recon.triangulation.measure.BandLog.describe`); default: the grid's radii.
    TRUNCATED and SATURATED_PLATEAU rows count as searched, not measured.
    """
    if not 0.0 <= min_fraction <= 1.0:
        raise ValueError(f"min_fraction must be in [0, 1], got {min_fraction}")
    r0, r1 = grid.r_range_mm
    found = searched_band is not None
    band = searched_band if found else f"r = {r0:.3f}–{r1:.3f} mm"
    searched = sorted({v for c in coverages for v in c.views} | set(views))
    names = ", ".join(searched) if searched else "none (no view window on this grid)"
    empty = [c for c in coverages if c.n_valid == 0]
    if empty:
        which = (f"{len(empty)} of {len(coverages)} sections" if len(coverages) > 1
                 else "the section")
        pred = [c.predicted_deg for c in empty if c.predicted_deg is not None]
        windows = f" (their θ windows cover {max(pred):.1f}°)" if pred else ""
        hint = ("no stripe was found at any radius the rig can image (no laser line, too dark "
                "for the threshold, or the object outside the field): check the image, or give "
                "--radius-mm and --band-mm" if found else
                "the object or its stripe lies outside that band (or the image has no laser "
                "line): give --radius-mm near the object's radius and a --band-mm that holds it, "
                "or leave --radius-mm out to find the band from the image")
        return f"no valid point in {which}: views {names} searched over {band}{windows}; {hint}"
    low = [c for c in coverages if c.fraction is not None and c.fraction < min_fraction]
    if low:
        worst = min(low, key=lambda c: c.fraction)
        return (f"{len(low)} of {len(coverages)} section(s) measured less than "
                f"{min_fraction:.0%} of the coverage their views predict (worst: section "
                f"{worst.section}, {worst.measured_deg:.1f}° of {worst.predicted_deg:.1f}°, "
                f"views {', '.join(worst.views) or 'none'}) over {band}; "
                + ("the profile may leave the band (a wider --band-mm), or parts of the section "
                   "are hidden or unlit" if found else
                   "the object may be off the axis or outside the band: widen --band-mm, set "
                   "--radius-mm, or leave --radius-mm out to find the band from the image")
                + " (--min-coverage sets the share)")
    return None
