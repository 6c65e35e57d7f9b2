"""Image → 3-D, in two parts side by side:

- :mod:`lts360.recon.calibration`: images of chessboards → the rig's calibration (camera,
  mirrors, laser plane, their uncertainty, the §4.4 view offsets);
- :mod:`lts360.recon.triangulation`: an image and a calibration → a measured section (inverse
  triangulation of paper §3.2, peak detectors, the classical baseline, clouds).

The two parts import neither each other; what both need lies below them:
:mod:`lts360.recon.model` (the :class:`Calibration` every measurement reads),
:mod:`lts360.recon.images` (an image's pixels, the detector's threshold and saturation),
:mod:`lts360.recon.lines` (Steger line centres) and :mod:`lts360.recon.view_points` (each
view's raw points of a round section).

Never imports :mod:`lts360.simulator` or any ground truth: it runs on real camera images and
a real calibration file.  Import the submodules directly; the most used names are here.
"""

from lts360.recon.model import Calibration, MirrorPlane, load_calibration, save_calibration
from lts360.recon.triangulation.cloud import Cloud, read_cloud, write_cloud
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import (
    InverseResult,
    estimate_view_offsets,
    inverse_triangulate,
    plan_inverse,
)
from lts360.recon.triangulation.peaks import Quality, detect_peaks

__all__ = ["Calibration", "MirrorPlane", "load_calibration", "save_calibration", "Cloud",
           "read_cloud", "write_cloud", "CylGrid", "InverseResult", "estimate_view_offsets",
           "inverse_triangulate", "plan_inverse", "Quality", "detect_peaks"]
