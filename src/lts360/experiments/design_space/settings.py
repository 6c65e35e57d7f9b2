"""The study's fixed settings, the optimum's criterion and the ``START:STOP:STEP`` axes."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

#: (alpha_deg, beta_deg) of the paper's rig, marked in the figures.
PAPER_DESIGN = (40.0, 90.0)
#: Radius of the section of the geometry metrics (a Ø20 mm part).
SECTION_RADIUS_MM = 10.0
#: θ step of the geometry metrics (coverage()'s default).
COVERAGE_STEP_DEG = 0.1
#: Object of the Monte Carlo measurement.
GAUGE_SPEC = "plug-gauge"
#: Inverse-triangulation grid of the Monte Carlo measurement: a modest grid (1440 θ × 401 r).
#: The θ step does not matter for the circle fit: paper rig, 24 draws (2026-11-23), radius std
#: 1.54 µm at 0.1°, 0.25° and 0.5° alike (draw-by-draw correlation 0.9998 at 0.1° / 0.25°).
THETA_STEP_DEG = 0.25
R_STEP_MM = 0.005
#: Half-width of the radial search band about the true radius (mm); also the segment of
#: ``ghost_in_band_pct``.
BAND_MM = 1.0
#: Fewest valid points for a circle fit of one draw.
MIN_POINTS = 10
#: A double-reflection stripe image closer than this to a search segment disturbs it: the
#: stripe is ~1 px σ wide, and the centroid integrates the run above a 10 % threshold, ±2σ.
GHOST_TOLERANCE_PX = 3.0
#: Samples along a search segment for ``ghost_in_band_pct`` (< 0.5 px apart for ±1 mm).
_SEGMENT_SAMPLES = 41
#: Values of ``status``.
STATUS = {0: "ok", 1: "invalid rig", 2: "no measurement"}
#: Trial settings recorded in every trial's params (so the plan covers them).
_DEFAULTS = {"draws": 8, "spp": 16, "scale": 1.0}
#: Largest number of values :func:`parse_range` returns.
MAX_RANGE_VALUES = 10_000

_SCALAR_METRICS = ("coverage_deg", "coverage_single_deg", "overlap_direct_left_deg",
                   "overlap_direct_right_deg", "overlap_direct_mirror_deg",
                   "overlap_mirror_mirror_deg", "image_margin_px", "multi_reflection_pct",
                   "ghost_in_band_pct", "multi_lit_pct", "radius_std_mm", "radius_mean_error_mm",
                   "point_rms_mm", "measured_coverage_deg", "n_points", "n_failed_draws",
                   "exposure_time_s", "seconds_render", "seconds_trial")


@dataclasses.dataclass(frozen=True)
class OptimumCriterion:
    """Which rigs qualify for the optimum; the optimum is the qualifying rig with the smallest
    ``radius_std_mm``.

    Attributes
    ----------
    min_coverage_deg : float
        Least ``coverage_single_deg`` (360° less one θ step of the coverage grid: rounding).
    min_overlap_deg : float, >=0
        Least direct/mirror and mirror/mirror overlap: enough common points to register the
        views (the paper's rig has 37.6° and 7.7°).
    max_multi_reflection_pct : float, >=0
        Largest ``multi_reflection_pct``.
    """

    min_coverage_deg: float = 360.0 - COVERAGE_STEP_DEG
    min_overlap_deg: float = 5.0
    max_multi_reflection_pct: float = 0.0

    def describe(self) -> str:
        return (f"single-view coverage ≥ {self.min_coverage_deg:g}°, direct/mirror and "
                f"mirror/mirror overlap ≥ {self.min_overlap_deg:g}°, multiple-reflection share "
                f"≤ {self.max_multi_reflection_pct:g} %; among those the smallest radius "
                "standard deviation")


OPTIMUM_CRITERION = OptimumCriterion()


# --- ranges -------------------------------------------------------------------------------------

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"


def parse_range(text: str) -> np.ndarray:
    """Values of a ``START:STOP:STEP`` range, the end included, or of a single value.

    ``"20:70:5"`` → ``[20, 25, …, 70]``; ``"40"`` → ``[40]``.  The values are
    ``START + k·STEP`` up to STOP (inclusive, within 1e-9 of a step): ``"20:70:7"`` ends at 69.

    Parameters
    ----------
    text : str
        ``START:STOP:STEP`` with ``STEP > 0`` and ``STOP >= START``, or one number.

    Returns
    -------
    (n,) float

    Raises
    ------
    ValueError
        Anything else; the message quotes the text.
    """
    if not isinstance(text, str):
        raise ValueError(f"range: expected a string START:STOP:STEP or a single number, "
                         f"got {text!r}")
    parts = [p.strip() for p in text.strip().split(":")]
    if len(parts) not in (1, 3) or not all(re.fullmatch(_NUMBER, p) for p in parts):
        raise ValueError(f"range {text!r}: expected START:STOP:STEP (e.g. 20:70:5) or a single "
                         "number (e.g. 40)")
    values = [float(p) for p in parts]
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"range {text!r}: values must be finite")
    if len(values) == 1:
        return np.array(values)
    start, stop, step = values
    if not step > 0:
        raise ValueError(f"range {text!r}: STEP must be > 0, got {step:g}")
    if stop < start:
        raise ValueError(f"range {text!r}: STOP ({stop:g}) must be >= START ({start:g})")
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    if n > MAX_RANGE_VALUES:
        raise ValueError(f"range {text!r}: {n} values, more than {MAX_RANGE_VALUES}")
    return np.round(start + step * np.arange(n), 10)


def _range_text(values) -> str:
    """The ``parse_range`` text of a sorted axis (a comma list if it is not uniform)."""
    v = [float(x) for x in values]
    if len(v) == 1:
        return f"{v[0]:g}"
    steps = np.diff(v)
    if np.allclose(steps, steps[0], rtol=0, atol=1e-9 * max(1.0, abs(steps[0]))):
        return f"{v[0]:g}:{v[-1]:g}:{steps[0]:g}"
    return ",".join(f"{x:g}" for x in v)


def _axis(name: str, values) -> list[float]:
    arr = parse_range(values) if isinstance(values, str) else np.asarray(values, dtype=float)
    if arr.ndim != 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be a range text or a non-empty 1-D sequence of finite "
                         f"numbers, got {values!r}")
    if len(np.unique(arr)) != arr.size:
        raise ValueError(f"{name}: values must be unique, got {arr.tolist()}")
    return [float(v) for v in np.sort(arr)]
