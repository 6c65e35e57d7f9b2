"""``lts360 study design-space``: the rig's design angles α and β swept over a grid (issue 6).

Every rig of the grid is the paper preset (``presets/paper.toml``) with only
``design.alpha_deg`` (triangulation angle between the laser plane and the camera axis) and
``design.beta_deg`` (angle between the mirrors) changed; everything else — distances, mirror
size, camera, focus, laser, sensor — stays as the preset has it.  One trial is one rig.  A
combination that the rig validation rejects (:class:`~lts360.scenes.rig.RigError`, e.g.
β < 60°) is not an error of the study: its trial records NaN metrics and ``status = 1``.

Metrics of a trial
------------------
Geometry (no rendering; :func:`lts360.scenes.coverage.coverage` of a Ø20 mm section,
``radius_mm = 10``, θ step 0.1°, light paths with up to two mirror reflections):

``coverage_deg``
    Angle of the section measured (seen and lit) in at least one view, double reflections
    included — ``CoverageResult.coverage_deg``.
``coverage_single_deg``
    The same for the views the reconstruction uses: direct and single mirror views.
``overlap_direct_left_deg``, ``overlap_direct_right_deg``, ``overlap_mirror_mirror_deg``
    Angle measured by both views of the pair (``CoverageResult.overlap_deg``);
    ``overlap_direct_mirror_deg`` is the smaller of the two direct/mirror overlaps.
``image_margin_px``
    Smallest distance of a measured point's image from the image border
    (``CoverageResult.image_margin_px``).
``multi_reflection_pct``
    Share of the 360° (in %) at which a point measured by a single view (direct, left or
    right) is *also* measured — seen and lit — through a double reflection (``left-right`` or
    ``right-left``): the frame then holds a second stripe image of that very point, which the
    reconstruction does not use and which may fall into a search band.
``ghost_in_band_pct``
    Share of the 360° (in %) at which, in at least one single view that measures the point,
    the image of the radial search segment (``r ± BAND_MM``) passes within
    :data:`GHOST_TOLERANCE_PX` of a double-reflection stripe image (of any point): the
    inverse triangulation's profile there sees a second line.
``multi_lit_pct``
    Share of the 360° (in %) measured by a single view and reached by the laser along more
    than one path (directly and via a mirror, ...).  Informative only, not a disturbance here:
    the mirrors are parallel to the object axis, so every laser path stays in the sheet plane
    and lights the same curve (the stripe is brighter, not displaced).

Monte Carlo radius uncertainty (``draws = M > 0``): the plug gauge (``build_object
("plug-gauge")``, Ø19.9987 mm, on the axis) is rendered once per rig without noise
(``simulate_frame(noise="none", thin_lens=True)``); then the sensor noise and the speckle
are drawn ``M`` times on that stored radiance (:func:`~lts360.simulator.frame.sensor_image`,
``noise="realistic"``: EMVA 1288 temporal noise and a new speckle pattern per draw, the same
fixed-pattern noise — the same camera — in all) and each image is measured by inverse
triangulation (centroid, Keys; the direct and the single mirror views) with the frame's true
calibration on the grid θ step :data:`THETA_STEP_DEG`, r step :data:`R_STEP_MM`, band
``±BAND_MM`` about the true radius, and a circle is fitted to all valid points:

``radius_error_mm`` (draw)
    Fitted minus true radius, per draw (NaN where fewer than :data:`MIN_POINTS` points).
``radius_std_mm``
    Standard deviation (ddof = 1) of the fitted radius over the draws: **the radius
    uncertainty** of the rig (noise and speckle only; the calibration is exact).
``radius_mean_error_mm``
    Mean of ``radius_error_mm``: the bias left by the optics and the sheet.
``point_rms_mm``
    RMS over all points of all draws of (distance from the true axis − true radius).
``measured_coverage_deg``, ``n_points``
    Mean over the draws of the angle with at least one valid view and of the point count.
``n_failed_draws``
    Draws with fewer than :data:`MIN_POINTS` valid points.

``status`` is 0 (ok), 1 (invalid rig: NaN everywhere) or 2 (rendered, but no draw gave a
measurement); :func:`rig_status` gives the message.  ``seconds_render`` and
``seconds_trial`` are wall times.

The optimum (:data:`OPTIMUM_CRITERION`): among the valid rigs with full single-view
coverage, both overlaps at least ``min_overlap_deg`` and no multiple-reflection share, the
one with the smallest ``radius_std_mm``.  With ``M`` draws the standard deviation itself
is uncertain by about ``1/√(2(M−1))`` (27 % for M = 8): neighbours within that are ties.
"""

from __future__ import annotations

from lts360.experiments.design_space.report import format_design_space
from lts360.experiments.design_space.settings import (
    BAND_MM,
    GAUGE_SPEC,
    GHOST_TOLERANCE_PX,
    MIN_POINTS,
    OPTIMUM_CRITERION,
    PAPER_DESIGN,
    R_STEP_MM,
    SECTION_RADIUS_MM,
    STATUS,
    THETA_STEP_DEG,
    OptimumCriterion,
    parse_range,
)
from lts360.experiments.design_space.study import run_design_space_study
from lts360.experiments.design_space.trial import (
    design_rig,
    design_space_trial,
    geometry_metrics,
    rig_status,
)

__all__ = ["parse_range", "design_rig", "rig_status", "geometry_metrics", "design_space_trial",
           "run_design_space_study", "format_design_space", "OptimumCriterion",
           "OPTIMUM_CRITERION", "PAPER_DESIGN", "STATUS", "SECTION_RADIUS_MM", "THETA_STEP_DEG",
           "R_STEP_MM", "BAND_MM", "MIN_POINTS", "GHOST_TOLERANCE_PX", "GAUGE_SPEC"]
