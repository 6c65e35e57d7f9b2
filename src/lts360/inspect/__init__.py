"""Inspection of measured clouds as an industrial profile gauge reports it.

Per section: the least-squares centre and diameter, two-point diameters and calliper widths,
ovality (both named definitions), roundness RONt against the four ISO 12181 reference circles,
harmonics, coverage and gaps (:mod:`~lts360.inspect.section`); along a scan: trends, lumps and
neck-downs, the axis, straightness, cylindricity, the diameter's spectrum
(:mod:`~lts360.inspect.scan`); deviation from a nominal contour with a tolerance band
(:mod:`~lts360.inspect.nominal`); size and ovality tolerances and the verdict
(:mod:`~lts360.inspect.tolerances`); every quantity with u and U(k = 2)
(:mod:`~lts360.inspect.uncertainty`), the ISO 12181-2 default filter and the noise bias of the
extremes (:mod:`~lts360.inspect.extremes`); JSON, CSV, figures and one HTML page
(:mod:`~lts360.inspect.report`).  ``lts360 inspect`` runs :func:`~lts360.inspect.run.inspect_cloud`.

Imports ``recon`` (the cloud, the calibration), ``geometry`` and ``scenes`` (nominal contours
and the truth of rendered frames), never the simulator.
"""
