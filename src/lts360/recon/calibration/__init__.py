"""Images → calibration: the rig's camera, mirrors and laser plane from chessboard images
(paper §4.2–4.3), their uncertainty, and the §4.4 view offsets.

``board`` (a printed board's geometry), ``camera`` (Zhang's method on OpenCV corners),
``board_model`` (a board's image model: corners placed by fitting the pixels of its squares),
``mirrors`` (each mirror plane from the real and the mirrored board), ``laser_line_model``
and ``laser_plane`` (the laser line on a board, the plane through the lines),
``uncertainty`` (jackknife and least-squares covariances, drawn by the Monte Carlo study),
``compensation`` (paper §4.4) and ``from_images`` (the whole procedure on a folder of images
and its manifest).

The :class:`Calibration` it produces is :mod:`lts360.recon.model` (JSON in OpenCV's names),
re-exported here.  Never imports :mod:`lts360.simulator`, :mod:`lts360.scenes` or the
triangulation part: it runs on real images.
"""

from lts360.recon.model import Calibration, MirrorPlane, load_calibration, save_calibration

__all__ = ["Calibration", "MirrorPlane", "load_calibration", "save_calibration"]
