"""The digital twin of a measurement: the measured section rendered back through the
calibrated rig, to estimate and remove the line-centre bias of the whole chain (the sheet's
thickness on a curved surface, each view's defocus, pixel sampling, the detector).

Inputs are the calibration (geometry), the rig file (optics, laser, sensor: design values)
and the measured profile itself; never the truth.  Imports recon, simulator, scenes and
geometry; recon never imports it (it offers a ``correct`` hook instead).
"""

from lts360.twin.debias import TwinCorrector, TwinLog, twin_corrected, twin_corrected_raw
from lts360.twin.profile import (
    SectionProfile,
    placed_profile,
    prism_mesh,
    ray_radii,
    section_profile,
    view_offsets,
)
from lts360.twin.rig import CalibratedCamera, twin_rig

__all__ = ["TwinCorrector", "TwinLog", "twin_corrected", "twin_corrected_raw", "SectionProfile", "prism_mesh", "ray_radii",
           "section_profile", "view_offsets", "placed_profile", "CalibratedCamera", "twin_rig"]
