"""Figures of the rig, its coverage and the objects' sections (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lts360.scenes.coverage import CoverageResult  # noqa: E402
from lts360.scenes.rig import Rig  # noqa: E402

__all__ = ["VIEW_COLOURS", "plot_rig", "plot_sections"]

#: Colours of the views, as in the paper's figures (red front, blue/green mirrors).
VIEW_COLOURS = {"direct": "tab:red", "left": "tab:blue", "right": "tab:green",
                "left-right": "tab:purple", "right-left": "tab:orange"}


def _save(fig, path: Path) -> Path:
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    tmp.replace(path)
    return path


def plot_rig(rig: Rig, cov: CoverageResult, path: Path) -> Path:
    """Top view of the rig with the laser fan, the mirrors, the camera and the covered section,
    and the image plane with every view's projected section."""
    fig, (ax, axi) = plt.subplots(1, 2, figsize=(13, 5.8))
    cam = rig.camera
    c = cam.center_mm
    las = rig.laser
    half = np.radians(las.fan_angle_deg) / 2
    reach = 1.6 * np.linalg.norm(las.origin_mm)
    for s in (-1, 1):
        rot = np.array([[np.cos(s * half), -np.sin(s * half)], [np.sin(s * half), np.cos(s * half)]])
        end = las.origin_mm[:2] + reach * rot @ las.direction[:2]
        ax.plot([las.origin_mm[0], end[0]], [las.origin_mm[1], end[1]], color="tab:red", lw=0.8,
                ls="--")
    ax.plot(*las.origin_mm[:2], "s", color="tab:red", label="laser (fan 50°)" if las.fan_angle_deg == 50 else "laser")
    for m in rig.mirrors:
        corners = m.corners_mm
        ax.plot(corners[:2, 0], corners[:2, 1], color="k", lw=3)
        mid = m.center_mm[:2]
        ax.annotate(f"{m.name} mirror", mid, textcoords="offset points", xytext=(0, 8), ha="center")
    ax.plot(c[0], c[1], "^", color="k", ms=9, label=f"camera (z = {c[2]:.0f} mm)")
    ax.plot([c[0], c[0] + 40 * cam.optical_axis[0]], [c[1], c[1] + 40 * cam.optical_axis[1]], "k-", lw=0.8)
    th = cov.theta_rad
    r = cov.radius_mm
    for view, mask in cov.measured.items():
        if mask.any():
            rr = r * (1.0 + 0.12 * (list(cov.measured).index(view) + 1))
            pts = np.where(mask, rr, np.nan)
            ax.plot(pts * np.cos(th), pts * np.sin(th), color=VIEW_COLOURS.get(view, "grey"), lw=2.5,
                    label=f"{view}: {cov.measured_deg(view):.1f}°")
    ax.plot(r * np.cos(th), r * np.sin(th), color="0.3", lw=1)
    ax.set_aspect("equal")
    ax.set_xlabel("x / mm")
    ax.set_ylabel("y / mm")
    ax.set_title(f"{rig.name} rig, top view — section Ø{2 * r:g} mm, coverage {cov.coverage_deg:.1f}°")
    ax.legend(loc="lower left", fontsize=8)
    ax.grid(alpha=0.3)

    w, h = cam.image_size
    axi.add_patch(plt.Rectangle((-0.5, -0.5), w, h, fill=False, color="k"))
    for view, uv in cov.image_uv.items():
        mask = cov.measured[view]
        if mask.any():
            axi.plot(np.where(mask, uv[:, 0], np.nan), np.where(mask, uv[:, 1], np.nan), ".",
                     ms=1.5, color=VIEW_COLOURS.get(view, "grey"), label=view)
    axi.set_xlim(-40, w + 40)
    axi.set_ylim(h + 40, -40)
    axi.set_aspect("equal")
    axi.set_title(f"image {w}×{h}: stripes of the section, margin "
                  f"{cov.image_margin_px(cam.image_size):.0f} px")
    axi.legend(loc="lower right", fontsize=8, markerscale=6)
    return _save(fig, path)


def plot_sections(sections: dict[str, tuple[np.ndarray, np.ndarray]], path: Path) -> Path:
    """Polar plots of true sections ``{name: (theta_rad, r_mm)}`` at z = 0 (object frame)."""
    n = len(sections)
    cols = min(n, 5)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.3 * rows))
    for ax, (name, (th, r)) in zip(np.ravel(axes), sections.items()):
        ax.plot(r * np.cos(th), r * np.sin(th), "k-", lw=1)
        ax.set_aspect("equal")
        ax.set_title(name, fontsize=9)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in np.ravel(axes)[n:]:
        ax.axis("off")
    fig.suptitle("True sections at z = 0 (object frame, mm)")
    return _save(fig, path)
