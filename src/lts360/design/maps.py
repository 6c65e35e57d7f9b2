"""Two-parameter maps of the model (any two free parameters, the others at the base rig)."""

from __future__ import annotations

import numpy as np

from lts360.design.model import Conditions, evaluate_batch
from lts360.design.params import DesignSpace

__all__ = ["design_map", "plot_map", "QUANTITIES"]

#: What a map can show: key of :func:`lts360.design.model.evaluate_batch` → label.
QUANTITIES = {"U_um": "U(k=2) of the radius, worst case (µm)",
              "sigma_R_noise_um": "σ of the radius from the image's noise, worst case (µm)",
              "sigma_R_comp_um": "σ of the radius from the §4.4 compensation, worst case (µm)",
              "sigma_R_cal_um": "σ of the radius from the calibration, worst case (µm)",
              "point_rms_um": "per-point σ_r, rms, worst case (µm)",
              "coverage_deg": "single-view coverage, smooth, worst case (°)",
              "objective": "objective: U + penalties (µm)"}


def design_map(space: DesignSpace, x_name: str, y_name: str, cond: Conditions, *,
               n: int = 100) -> dict:
    """The model on an ``n × n`` grid of two free parameters over their bounds.

    Returns
    -------
    dict
        ``x``, ``y`` : (n,) axes; every quantity of :data:`QUANTITIES` as (n, n) (rows: y);
        ``U_um``, the σ shares and ``point_rms_um`` are the largest over the cases, ``coverage_deg`` the
        smallest.
    """
    ix, iy = space.free.index(x_name), space.free.index(y_name)
    xs = np.linspace(*space.bounds[x_name], n)
    ys = np.linspace(*space.bounds[y_name], n)
    X = np.tile(space.base_x(), (n * n, 1))
    gx, gy = np.meshgrid(xs, ys)
    X[:, ix], X[:, iy] = gx.ravel(), gy.ravel()
    b = evaluate_batch(space, X, cond)
    out = {"x": xs, "y": ys, "x_name": x_name, "y_name": y_name,
           "U_um": b["U_um"].max(axis=1).reshape(n, n),
           "point_rms_um": b["point_rms_um"].max(axis=1).reshape(n, n),
           **{k: b[k].max(axis=1).reshape(n, n)
              for k in ("sigma_R_noise_um", "sigma_R_comp_um", "sigma_R_cal_um")},
           "coverage_deg": b["coverage_deg"].min(axis=1).reshape(n, n),
           "objective": b["objective"].reshape(n, n)}
    return out


def plot_map(m: dict, quantity: str, path, *, base_xy=None, min_coverage_deg: float = 359.0
             ) -> None:
    """A PNG of one quantity, the region under ``min_coverage_deg`` hatched, the base rig
    starred."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 5.0), dpi=110)
    z = m[quantity]
    vmax = np.nanpercentile(z, 95) if quantity != "coverage_deg" else 360.0
    im = ax.pcolormesh(m["x"], m["y"], z, shading="auto", vmax=vmax)
    fig.colorbar(im, ax=ax, label=QUANTITIES[quantity])
    bad = (m["coverage_deg"] < min_coverage_deg).astype(float)
    if bad.any() and bad.min() < 1:
        ax.contourf(m["x"], m["y"], bad, levels=[0.5, 1.5], hatches=["//"], colors="none")
        ax.contour(m["x"], m["y"], m["coverage_deg"], levels=[min_coverage_deg], colors="w",
                   linewidths=0.8)
    if base_xy is not None:
        ax.plot(*base_xy, "*", color="w", ms=12, mec="k")
    ax.set_xlabel(m["x_name"])
    ax.set_ylabel(m["y_name"])
    ax.set_title(f"model: {QUANTITIES[quantity]}\n(hatched: coverage < {min_coverage_deg:g}°)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
