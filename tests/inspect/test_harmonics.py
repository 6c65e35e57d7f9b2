import numpy as np
import pytest

from lts360.inspect.harmonics import fit_harmonics


def test_a_known_series_is_recovered_on_both_paths():
    th = -np.pi + np.arange(720) * (2 * np.pi / 720)
    r = 8.0 + 0.1 * np.cos(2 * th - 0.3) + 0.02 * np.cos(3 * (th - 0.5)) + 0.005 * np.sin(7 * th)
    full = fit_harmonics(th, r)  # uniform full circle: the FFT
    keep = (th < 1.0) | (th > 1.2)
    gap = fit_harmonics(th[keep], r[keep])  # with a gap: least squares
    # the FFT is exact; an 11° gap leaves orders near 50 ill-conditioned, and the normal
    # equations (with their 1e-10 ridge) lose up to ~1e-7 mm
    for h, tol in ((full, 1e-12), (gap, 1e-6)):
        assert h.mean_mm == pytest.approx(8.0, abs=tol)
        assert h.amplitude_mm[1] == pytest.approx(0.1, abs=tol)
        assert h.amplitude_mm[2] == pytest.approx(0.02, abs=tol)
        assert h.amplitude_mm[6] == pytest.approx(0.005, abs=tol)
        assert h.phase_deg[2] == pytest.approx(np.degrees(0.5), abs=1e-3)
        assert h.dominant() == (2, pytest.approx(0.1))
