"""Image → section: inverse triangulation (paper §3.2) and its parts.

``grid`` (the cylindrical grid in the laser plane), ``views`` (each view's θ window and its
mirror matrices T_π), ``interp`` (Keys bicubic sampling), ``peaks`` (laser-peak detectors along
a radial profile), ``inverse`` (the numpy reference), ``fast`` (the Dr.Jit kernel), ``classic``
(the image-space baseline: Steger centres, rays ∩ laser plane), ``measure`` (frames and scans to
clouds) and ``cloud`` (the measured point cloud as PLY).

Reads a :class:`lts360.recon.model.Calibration`; never imports the calibration part
(:mod:`lts360.recon.calibration`), :mod:`lts360.simulator` or :mod:`lts360.scenes`.
"""
