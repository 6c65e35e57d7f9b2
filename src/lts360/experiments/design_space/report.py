"""The design-space tables, figures and README."""

from __future__ import annotations

import datetime
import math
import os
import platform
from pathlib import Path

import numpy as np

from lts360.experiments.design_space.settings import (
    BAND_MM,
    COVERAGE_STEP_DEG,
    GAUGE_SPEC,
    GHOST_TOLERANCE_PX,
    PAPER_DESIGN,
    R_STEP_MM,
    SECTION_RADIUS_MM,
    THETA_STEP_DEG,
    OptimumCriterion,
    _range_text,
)

# --- reporting ----------------------------------------------------------------------------------

#: (key, title, scale, format) of the terminal tables.
_TABLES = (("coverage_single_deg", "single-view coverage (°)", 1.0, "{:5.1f}"),
           ("overlap_direct_mirror_deg", "direct/mirror overlap, smaller side (°)", 1.0,
            "{:5.1f}"),
           ("overlap_mirror_mirror_deg", "mirror/mirror overlap (°)", 1.0, "{:5.1f}"),
           ("multi_reflection_pct", "multiple-reflection share (%)", 1.0, "{:5.1f}"),
           ("radius_std_mm", "radius standard deviation over the draws (µm)", 1e3, "{:5.2f}"))


def _fmt_opt(cell: dict | None, label: str) -> str:
    if cell is None:
        return f"{label}: none"

    def um(key):
        v = cell.get(key)
        return "—" if v is None else f"{v * 1e3:.2f} µm"

    def deg(key):
        v = cell.get(key)
        return "—" if v is None else f"{v:.1f}°"

    def pct(key):
        v = cell.get(key)
        return "—" if v is None else f"{v:.1f} %"

    return (f"{label}: α = {cell['alpha_deg']:g}°, β = {cell['beta_deg']:g}° — radius std "
            f"{um('radius_std_mm')}, mean error {um('radius_mean_error_mm')}, point rms "
            f"{um('point_rms_mm')}, coverage {deg('coverage_single_deg')} (measured "
            f"{deg('measured_coverage_deg')}), overlaps {deg('overlap_direct_mirror_deg')} / "
            f"{deg('overlap_mirror_mirror_deg')}, multiple reflections "
            f"{pct('multi_reflection_pct')}")


def format_design_space(summary: dict) -> str:
    """Terminal tables (α rows, β columns) of the main metrics, then the paper rig and the
    optimum."""
    g = summary["grid"]
    betas = g["beta_deg"]
    lines = []
    for key, title, factor, fmt in _TABLES:
        lines.append(f"{title}:")
        lines.append("  α \\ β " + "".join(f"{b:>7g}" for b in betas))
        for a, row in zip(g["alpha_deg"], g[key]):
            cells = "".join(f"{'—':>7s}" if v is None else f"{fmt.format(v * factor):>7s}"
                            for v in row)
            lines.append(f"  {a:>5g} " + cells)
        lines.append("")
    for inv in summary.get("invalid", []):
        lines.append(f"α = {inv['alpha_deg']:g}°, β = {inv['beta_deg']:g}°: {inv['status']}")
    lines.append(_fmt_opt(summary.get("paper"), "paper rig"))
    lines.append(_fmt_opt(summary.get("optimum"), "optimum"))
    lines.append(f"  (criterion: {summary['criterion']['text']})")
    return "\n".join(lines)


def _edges(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if len(v) == 1:
        return np.array([v[0] - 2.5, v[0] + 2.5])
    mid = (v[1:] + v[:-1]) / 2.0
    return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])


#: (file stem, [(variable, colour-bar label, factor)]) of the figures.
_FIGURES = (
    ("design-space-coverage", [("coverage_single_deg", "single-view coverage (°)", 1.0),
                               ("image_margin_px", "image margin (px)", 1.0)]),
    ("design-space-overlap", [("overlap_direct_mirror_deg", "direct/mirror overlap (°)", 1.0),
                              ("overlap_mirror_mirror_deg", "mirror/mirror overlap (°)", 1.0)]),
    ("design-space-multiple-reflections",
     [("multi_reflection_pct", "double-reflection image of a measured point (% of 360°)", 1.0),
      ("ghost_in_band_pct", "double-reflection stripe in a search band (% of 360°)", 1.0)]),
    ("design-space-radius-uncertainty",
     [("radius_std_mm", "radius std over the draws (µm)", 1e3),
      ("point_rms_mm", "per-point rms (µm)", 1e3)]),
)


#: Heat maps with at most this many cells print each cell's value.
_MAX_ANNOTATED_CELLS = 400


def _plot_all(grid, summary: dict, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = np.asarray(grid["alpha_deg"].values, dtype=float)
    b = np.asarray(grid["beta_deg"].values, dtype=float)
    ea, eb = _edges(a), _edges(b)
    opt = summary.get("optimum")
    paths = []
    for stem, panels in _FIGURES:
        fig, axes = plt.subplots(1, len(panels), figsize=(6.0 * len(panels), 4.6), squeeze=False)
        for ax, (var, label, factor) in zip(axes[0], panels):
            z = np.asarray(grid[var].values, dtype=float) * factor
            ax.set_facecolor("0.85")  # NaN: invalid rig or not measured
            mesh = ax.pcolormesh(eb, ea, np.ma.masked_invalid(z), cmap="viridis", shading="flat")
            fig.colorbar(mesh, ax=ax, label=label)
            if z.size <= _MAX_ANNOTATED_CELLS:
                for (i, j), v in np.ndenumerate(z):
                    if np.isfinite(v):
                        ax.text(b[j], a[i], f"{v:.3g}", ha="center", va="center", fontsize=6,
                                color="w" if v < np.nanmean(z) else "k")
            ax.plot(PAPER_DESIGN[1], PAPER_DESIGN[0], marker="*", ms=16, mfc="white", mec="k",
                    ls="none", label=f"paper (α {PAPER_DESIGN[0]:g}°, β {PAPER_DESIGN[1]:g}°)")
            if opt is not None:
                ax.plot(opt["beta_deg"], opt["alpha_deg"], marker="o", ms=12, mfc="none",
                        mec="red", mew=2, ls="none",
                        label=f"optimum (α {opt['alpha_deg']:g}°, β {opt['beta_deg']:g}°)")
            ax.set_xlim(eb[0], eb[-1])
            ax.set_ylim(ea[0], ea[-1])
            ax.set_xlabel("β, angle between the mirrors (°)")
            ax.set_ylabel("α, triangulation angle (°)")
            ax.legend(loc="lower left", fontsize=7, framealpha=0.8)
        fig.suptitle("design space of the paper rig (grey: invalid rig or no value)")
        fig.tight_layout()
        path = out / f"{stem}.png"
        tmp = path.with_name(f".{path.stem}.tmp.png")
        fig.savefig(tmp, dpi=110)
        plt.close(fig)
        tmp.replace(path)
        paths.append(path)
    return paths


def _machine() -> str:
    try:
        import mitsuba as mi

        from lts360.simulator.render import default_variant

        variant = mi.variant() or f"{default_variant()} (set by the trials)"
        mitsuba = f"Mitsuba {mi.__version__}, variant {variant}"
    except ImportError:
        mitsuba = "Mitsuba not installed"
    return (f"{platform.node()} — {platform.platform()}, {platform.machine()}, "
            f"{os.cpu_count()} CPUs, Python {platform.python_version()}, {mitsuba}")


def _readme(summary: dict, criterion: OptimumCriterion) -> str:
    s = summary["settings"]
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    g = summary["grid"]
    lines = [
        "# Design space of the 360° laser triangulation rig (α, β)",
        "",
        "Written by `lts360.experiments.design_space.run_design_space_study`.",
        "",
        "```",
        summary["command"],
        "```",
        "",
        f"- date: {now}",
        f"- machine: {_machine()}",
        f"- grid: α = {_range_text(g['alpha_deg'])}° (n = {len(g['alpha_deg'])}), "
        f"β = {_range_text(g['beta_deg'])}° (n = {len(g['beta_deg'])}): "
        f"{summary['n_trials']} rigs; {summary['n_run']} run by this call, "
        f"{summary['n_trials'] - summary['n_run']} already on disk",
        f"- root seed {s['seed']} (trial i: `np.random.SeedSequence(seed).spawn(n)[i]`; in a "
        "trial, stream 0 seeds the render, streams 1..M the draws' noise and speckle)",
        f"- per rig: one render of `{GAUGE_SPEC}` (noise-free, {s['spp']} spp, thin lens, image "
        f"scale {s['scale']:g}), {s['draws']} draws of sensor noise and speckle, each measured "
        f"by inverse triangulation with the true calibration (θ step {THETA_STEP_DEG:g}°, "
        f"r step {R_STEP_MM * 1e3:g} µm, band ±{BAND_MM:g} mm) and a circle fit",
        f"- geometry: coverage() of a Ø{2 * SECTION_RADIUS_MM:g} mm section, θ step "
        f"{COVERAGE_STEP_DEG:g}°, up to two reflections",
        f"- wall time of this call {summary['seconds']:.1f} s; mean wall time of a valid "
        f"rig's trial (as stored, whenever it ran) {summary['seconds_per_trial']:.1f} s",
        "",
        "Every rig is the `paper` preset with only `design.alpha_deg` and `design.beta_deg` "
        "changed.",
        "",
        "## Result",
        "",
        f"Optimum criterion: {criterion.describe()}.",
        "",
        f"- {_fmt_opt(summary['optimum'], 'optimum')}",
        f"- {_fmt_opt(summary['paper'], 'paper rig')}",
    ]
    if summary["optimum"] is not None:
        lines.append(f"- rigs that qualify: {summary['optimum']['n_qualifying']}. With M draws the "
                     "standard deviation is itself uncertain by about 1/√(2(M−1)) "
                     f"({100 / math.sqrt(2 * max(s['draws'] - 1, 1)):.0f} % here): rigs within "
                     "that of the optimum are ties.")
    if summary["invalid"]:
        lines += ["", "Rigs without a result:", ""]
        lines += [f"- α = {i['alpha_deg']:g}°, β = {i['beta_deg']:g}°: {i['status']}"
                  for i in summary["invalid"]]
    lines += ["", "```", format_design_space(summary), "```", "",
              "## Metrics", "",
              "See the docstring of `lts360/experiments/design_space.py` for the exact "
              "definitions. In short:", "",
              "- `coverage_single_deg`: angle of the section measured (seen and lit) by the "
              "direct or a single mirror view; `coverage_deg` counts double reflections too.",
              "- `overlap_direct_mirror_deg` (smaller of direct/left and direct/right) and "
              "`overlap_mirror_mirror_deg`: angle measured by both views.",
              "- `image_margin_px`: least distance of a measured point's image from the border.",
              "- `multi_reflection_pct`: share of 360° where a point measured by a single view "
              "also appears, seen and lit, through a double reflection (a second stripe image "
              "of the point).",
              f"- `ghost_in_band_pct`: share of 360° where a double-reflection stripe image "
              f"lies within {GHOST_TOLERANCE_PX:g} px of a single view's ±{BAND_MM:g} mm search "
              "segment.",
              "- `radius_std_mm`: standard deviation of the fitted gauge radius over the draws "
              "(the radius uncertainty); `radius_mean_error_mm` its mean error; "
              "`point_rms_mm`: rms of the point radii about the true circle; "
              "`measured_coverage_deg`: angle with at least one valid point (mean over draws).",
              "", "## Files", "",
              "- `trials/results.nc`: every trial (runner layout, resumable: run the same "
              "command again to finish an interrupted study)",
              "- `grid.nc`: the results over (alpha_deg, beta_deg), with `status_text`",
              "- `summary.json`: this summary",
              "- " + ", ".join(f"`{Path(f).name}`" for f in summary["files"]["figures"])
              + ": heat maps (star: the paper's design, red circle: the optimum)", ""]
    return "\n".join(lines)
