"""The thresholds of the truth-free rejection (:mod:`lts360.recon.triangulation.reject`), in
one documented, frozen object.

Each threshold carries its reason and the measurement that set it (the examples study with
realistic noise, STUDIES.md; the commit named is where it was measured).  The defaults are
:data:`TOLERANCES`; a study or a user changes one with ``dataclasses.replace(TOLERANCES,
notch_depth_mm=0.1)`` and passes the values to the functions, whose keyword defaults read
this object.  Lengths in mm, slopes as |dr/dz|, angles in degrees.
"""

from __future__ import annotations

import dataclasses
import math

__all__ = ["RejectionTolerances", "TOLERANCES"]


@dataclasses.dataclass(frozen=True)
class RejectionTolerances:
    """Every threshold of the truth-free rejection, with why it has its value."""

    #: ``DISCONTINUOUS``: a residual off the running median beyond k robust σ.  Opt-in
    #: (``--continuity-k``); 6σ keeps a Gaussian profile's false rejections below 1e-8 (b7c4c87).
    continuity_k: float = 6.0
    #: Half-width of the running median (deg): short enough to follow a cable's strands
    #: (~15° a strand on Ø6 mm), long enough for ±10 samples at 0.1° (b7c4c87).
    continuity_window_deg: float = 2.0
    #: Below this a residual is never an outlier: a few times the pixel-locking scatter of a
    #: noise-free section (~3 µm rms, measured on the plug gauge; b7c4c87).
    continuity_floor_mm: float = 0.015
    #: ``FADING``: arc next to a faded stretch whose points are rejected.  The spurious points
    #: of the grooved shaft's helix and of a cable's valleys sit within 0.5 mm of such a gap
    #: (measured, 07ec9c2).
    fade_margin_mm: float = 0.5
    #: ``FADING``: the shortest faded stretch inside a view's window that counts (07ec9c2).
    fade_gap_mm: float = 0.3
    #: The narrow tier (a scan): a faded stretch of this much or more ...
    short_gap_mm: float = 0.1
    #: ... flags the line's last 0.07 mm before it (cable-6 spurious 1.18 → 0.96 %; one frame
    #: keeps the plain rule, where the tier would cost a gauge 0.6 %; be6c00a, 529f464).
    short_margin_mm: float = 0.07
    #: In a scan a faded stretch across which the profile is convex is kept: chords this far
    #: beyond its flanks (be6c00a) ...
    convex_reach_mm: float = 1.0
    #: ... which must bulge by this fraction of a circle's sagitta (0: lie above the chord at
    #: all; the round and axial tests do the separating, measured: alu pipe FADING 1141 → 168).
    convex_fraction: float = 0.0
    #: ... and along which the surface runs straighter than this between sections: a corner
    #: bulges too, and a shoulder's or a groove's flank is round in section (be6c00a).
    max_axial_slope: float = 0.3
    #: ... and where the section is round: its profile within this of its circle (be6c00a).
    round_tol_mm: float = 0.15
    #: ``NOTCH``: depth below the profile's chord.  A convex section lies above every chord,
    #: so only the smoothed profile's noise reaches it: ≤ 0.3 % of a round object's points
    #: with realistic noise at 80 µm (07ec9c2).
    notch_depth_mm: float = 0.08
    #: ``NOTCH``: the chords' half-lengths (arc): about twice the sheet's thickness seen at
    #: the camera's angle, the narrowest notch the detector cannot resolve (07ec9c2).
    notch_scales_mm: tuple = (0.5, 1.0)
    #: In a scan, no notch where the profile is within this of the section's circle: a round
    #: section's glints and noise (alu pipe 159 NOTCH points → 33), while a cable's valleys
    #: lie farther off it (b93fc9d).
    notch_round_tol_mm: float = 0.1
    #: In a scan, behind that test, a shallower notch is called (095c50d).
    scan_notch_depth_mm: float = 0.06
    #: ``FLANK``: a section whose profile differs from both neighbours' by more than this
    #: axial slope lies on a flank; also the least change of slope within two pitches that
    #: makes the flank short (a 27° cone keeps its slope and is measured; 095c50d, 2b48526).
    max_flank_slope: float = 0.15
    #: ``FLANK``: ... over at least this arc: a cable's noisy valleys differ from their
    #: neighbours' over 1–2°, a groove's or a shoulder's flank over much of the turn (095c50d).
    min_flank_arc_mm: float = 2.0
    #: ``FLANK`` at a scan's ends: an end section whose profile differs from its only
    #: neighbour's by more than ``max_flank_slope`` (over ``min_flank_arc_mm``) where that
    #: neighbour's slope beyond changes by as much (the surface turns within the last two
    #: pitches) is flagged too: it lies on the flank or past it, and no section beyond tells
    #: which, so its points are not trusted.  The cost: an end section just past a shoulder
    #: loses its points.  Measured: the undercut shaft's 5-section scan, whose end sections
    #: lie on its groove's 45° flanks: spurious points still valid 9.30 → 0.08 % (7.97 →
    #: 0.09 % with interreflections), mean coverage 270° → 225° (6d84b0c; STUDIES.md,
    #: Interreflections).
    flank_end_sections: bool = True
    #: The largest turn of the profile between neighbouring sections that ``screw_rate``
    #: seeks (deg): cable-6 turns 4.1°/mm, the grooved shaft 14.7°/mm at 0.68 mm pitch.
    max_screw_shift_deg: float = 10.0
    #: ``NEIGHBOURS``: θ samples either side a neighbour's rejection is widened by (cable-6
    #: 2.8 mm off the axis: 303 → 172 spurious points still valid; 0c6547c).
    neighbour_dilation: int = 1

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            values = v if isinstance(v, tuple) else (v,)
            if not values or not all(isinstance(x, (int, float)) and math.isfinite(x)
                                     and x >= 0 for x in values):
                raise ValueError(f"RejectionTolerances.{f.name}: must be finite and >= 0, "
                                 f"got {v!r}")


#: The defaults.
TOLERANCES = RejectionTolerances()
