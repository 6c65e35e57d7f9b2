"""Writing an inspection: ``inspection.json``, ``sections.csv``, figures and ``report.html``.

Everything is written into a temporary directory beside ``out`` and renamed onto it at the end,
so an interrupted or refused run leaves no half-written report.

Figures (matplotlib, object API, no global backend):

* ``polar_deviation.png`` — the key section (the worst against the nominal, else the least
  round): its deviation from the nominal (or from its LS circle) over θ, magnified, with the
  tolerance band and the four reference circles;
* ``along_z.png`` — diameters (LS, two-point min/max) and ovality over z with U(k = 2) bars,
  lumps and neck-downs shaded, true values where given;
* ``deviation_map.png`` — the deviation over θ × z (gaps blank);
* ``harmonics.png`` — the key section's harmonic amplitudes.

``report.html`` is one self-contained page: the tables and the figures as base64 PNG.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import shutil
from pathlib import Path

import numpy as np

from lts360.inspect.circles import REFERENCES
from lts360.inspect.profile import bin_profile
from lts360.inspect.run import Inspection

__all__ = ["write_report", "csv_rows", "key_section", "FIGURES"]

FIGURES = ("polar_deviation.png", "along_z.png", "deviation_map.png", "harmonics.png")
_REF_COLOURS = {"LSCI": "tab:blue", "MZCI": "tab:green", "MCCI": "tab:red", "MICI": "tab:purple"}


def _v(q):
    return None if q is None else q.get("value")


#: Decimals of a length in mm in the CSV: 0.1 µm, below every U it carries.
CSV_MM_DECIMALS = 4


def _csv_value(key: str, v):
    """A CSV cell: lengths to 0.1 µm, percentages and other floats to 4 decimals, booleans as
    ``true``/``false``, nothing as an empty cell."""
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return ""
        return f"{float(v):.{CSV_MM_DECIMALS if key.endswith('_mm') else 4}f}"
    return v


def csv_rows(data: dict) -> list[dict]:
    """One flat row per section: each value beside its expanded uncertainty ``U_k2_…``
    (k = 2), the point scatter as one standard deviation (``scatter_1sigma_mm``), true values
    where given; lengths in mm to 0.1 µm, booleans ``true``/``false``."""
    rows = []
    for s in data["sections"]:
        row = {"index": s["index"], "z_mm": s["z_mm"], "n_valid": s["n_valid"],
               "coverage_deg": round(s["coverage_deg"], 3),
               "scatter_1sigma_mm": s["scatter_mm"]}
        if "time_s" in s:  # a moving object
            row["time_s"], row["time_span_s"] = s["time_s"], s["time_span_s"]
        for key in ("centre_x_mm", "centre_y_mm", "d_ls_mm", "d_mean_mm", "d_min_mm",
                    "d_max_mm", "ovality_mm", "ovality_over_sum_pct", "ovality_over_mean_pct",
                    "calliper_min_mm", "calliper_max_mm"):
            row[key] = s[key]["value"]
            row["U_k2_" + key] = s[key]["U_k2"]
        for ref in REFERENCES:
            row[f"ront_{ref.lower()}_mm"] = s["ront_mm"][ref]["value"]
            row[f"U_k2_ront_{ref.lower()}_mm"] = s["ront_mm"][ref]["U_k2"]
        for key in ("a2_mm", "a3_mm"):
            row["harmonic_" + key] = s["harmonics"][key]["value"]
            row["U_k2_harmonic_" + key] = s["harmonics"][key]["U_k2"]
        row["dominant_order"] = s["harmonics"]["dominant_order"]
        if "nominal" in s:
            n = s["nominal"]
            row["deviation_min_mm"] = n["deviation_min_mm"]["value"]
            row["deviation_max_mm"] = n["deviation_max_mm"]["value"]
            row["U_k2_deviation_mm"] = n["deviation_max_mm"]["U_k2"]
            if "pass" in n:
                row["pass"] = n["pass"]
                row["conformance_iso14253"] = n["conformance_iso14253"]
        for name, c in s.get("checks", {}).items():
            row[f"{name}_pass"] = c["pass"]
            row[f"{name}_conformance_iso14253"] = c["conformance_iso14253"]
        t = s.get("truth")
        if t:
            for key in ("d_ls_mm", "d_min_mm", "d_max_mm", "ovality_mm", "a2_mm", "a3_mm"):
                row["true_" + key] = t[key]
            row["true_ront_mzci_mm"] = t["ront_mm"]["MZCI"]
        rows.append({k: _csv_value(k, v) for k, v in row.items()})
    return rows


def key_section(ins: Inspection) -> int:
    """Position (in ``ins.sections``) of the worst section: largest |deviation| from the
    nominal, else largest RONt(MZCI)."""
    if ins.deviations_mm:
        return int(np.argmax([np.max(np.abs(d)) for _, d in ins.deviations_mm]))
    return int(np.argmax([s.circles["MZCI"].ront_mm for s in ins.sections]))


def _figure(w, h):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    fig.subplots_adjust(left=0.11, right=0.97, bottom=0.12, top=0.92, hspace=0.12)
    return fig


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)  # no bbox="tight": it lays out twice
    return buf.getvalue()


def _fig_polar(ins: Inspection, k: int) -> bytes:
    s = ins.sections[k]
    c0 = s.ls.centre_mm
    if ins.deviations_mm:
        ring, dev = ins.deviations_mm[k]
        d = s.xy_mm - c0
        th, what = np.arctan2(d[:, 1], d[:, 0]), "deviation from the nominal"
        e = ring - c0  # the nominal's radius along each circle direction, below
        ref_r = (np.arctan2(e[:, 1], e[:, 0]), np.hypot(e[:, 0], e[:, 1]))
    else:
        th, dev = s.profile.theta_rad, s.profile.r_mm - s.ls.radius_mm
        what, ref_r = "deviation from the LS circle", s.ls.radius_mm
    fig = _figure(6.4, 6.6)
    fig.subplots_adjust(left=0.08, right=0.92, bottom=0.2, top=0.92)
    ax = fig.add_subplot(projection="polar")
    o = np.argsort(th)
    dev_um = 1e3 * dev
    lim = [float(np.nanmin(dev_um)), float(np.nanmax(dev_um))]
    if ins.band is not None:
        lim = [min(lim[0], 1e3 * ins.band.lower_mm), max(lim[1], 1e3 * ins.band.upper_mm)]
    span = max(lim[1] - lim[0], 1e-3)
    base = lim[0] - 0.6 * span  # the plot's centre, so that negative deviations show
    ax.plot(th[o], dev_um[o] - base, ".", ms=1.5, color="k", label=what)
    t = np.linspace(-np.pi, np.pi, 721)
    if ins.band is not None:
        for v, lab in ((ins.band.upper_mm, "upper limit"), (ins.band.lower_mm, "lower limit")):
            ax.plot(t, np.full_like(t, 1e3 * v - base), "--", color="tab:orange", lw=1,
                    label=lab)
    u = np.column_stack([np.cos(t), np.sin(t)])
    for name, c in s.circles.items():
        # the circle's radius about the LS centre at θ, as a deviation from the LS radius; the
        # MZCI is its zone: the inner and the outer circle
        e = c.centre_mm - c0
        b = u @ e
        radii = (c.r_min_mm, c.r_max_mm) if name == "MZCI" else (c.radius_mm,)
        for j, radius in enumerate(radii):
            rho = b + np.sqrt(np.maximum(radius**2 - (e @ e - b * b), 0.0))
            if isinstance(ref_r, tuple):  # relative to the nominal, as the points
                o_n = np.argsort(ref_r[0])
                rho = rho - np.interp(t, ref_r[0][o_n], ref_r[1][o_n], period=2 * np.pi)
            else:
                rho = rho - ref_r
            label = (f"MZCI zone, two circles (RONt {1e3 * c.ront_mm:.1f} µm)" if name == "MZCI"
                     else f"{name} (on a gap's chord: not determined)"
                     if name in s.extra.get("undetermined", [])
                     else f"{name} (RONt {1e3 * c.ront_mm:.1f} µm)")
            ax.plot(t, 1e3 * rho - base, color=_REF_COLOURS[name], lw=1,
                    ls="--" if name == "MZCI" else "-", label=None if j else label)
    ax.set_rorigin(0)
    ax.set_ylim(0, lim[1] - base + 0.1 * span)
    from matplotlib.ticker import MaxNLocator

    ticks = [v for v in MaxNLocator(5, steps=[1, 2, 2.5, 5, 10]).tick_values(*lim)
             if lim[0] - 0.05 * span <= v <= lim[1] + 0.1 * span]
    ax.set_yticks(np.array(ticks) - base, [f"{v:g}" for v in ticks], fontsize=8)
    ax.set_title(f"section {s.index}, z = {s.z_mm:.2f} mm: {what} (µm)", fontsize=9)
    ax.legend(loc="upper left", bbox_to_anchor=(-0.05, -0.04), fontsize=7, ncol=2)
    return _png(fig)


def _fig_along_z(ins: Inspection) -> bytes:
    rows = ins.data["sections"]
    z = np.array([r["z_mm"] for r in rows])
    fig = _figure(7.5, 5.5)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for key, lab, col in (("d_ls_mm", "D (LS)", "tab:blue"), ("d_min_mm", "D min (two-point)",
                          "tab:green"), ("d_max_mm", "D max (two-point)", "tab:red")):
        v = np.array([np.nan if r[key]["value"] is None else r[key]["value"] for r in rows])
        ax1.errorbar(z, v, yerr=[r[key]["U_k2"] for r in rows], fmt=".-", ms=3, lw=0.8,
                     color=col, label=lab, capsize=2)
        if all(r.get("truth") for r in rows):
            ax1.plot(z, [r["truth"][key] for r in rows], "x:", color=col, lw=1, ms=4,
                     label=lab + " true")
    ov = np.array([np.nan if r["ovality_mm"]["value"] is None else r["ovality_mm"]["value"]
                   for r in rows])
    ax2.errorbar(z, 1e3 * ov, yerr=[1e3 * r["ovality_mm"]["U_k2"] for r in rows], fmt=".-",
                 ms=3, color="k", capsize=2, label="ovality Dmax − Dmin")
    if all(r.get("truth") for r in rows):
        ax2.plot(z, [1e3 * r["truth"]["ovality_mm"] for r in rows], "x:", color="k", ms=4,
                 label="true")
    for e in ins.data["scan"]["events"]:
        for ax in (ax1, ax2):
            ax.axvspan(e["z_start_mm"], e["z_end_mm"], alpha=0.15,
                       color="tab:red" if e["kind"] == "lump" else "tab:blue")
    ax1.set_ylabel("diameter (mm)")
    ax2.set_ylabel("ovality (µm)")
    ax2.set_xlabel("z (mm, stage)")
    ax1.legend(fontsize=7, ncol=2)
    ax2.legend(fontsize=7)
    ax1.set_title("diameters and ovality along the scan, bars U(k = 2)", fontsize=9)
    return _png(fig)


def _fig_map(ins: Inspection) -> bytes:
    nb = 720
    edges = np.linspace(-180, 180, nb + 1)
    rows = []
    for i, s in enumerate(ins.sections):
        if ins.deviations_mm:
            d = s.xy_mm - s.ls.centre_mm
            th, dev = np.degrees(np.arctan2(d[:, 1], d[:, 0])), ins.deviations_mm[i][1]
        else:
            p = bin_profile(s.xy_mm, s.ls.centre_mm)
            th, dev = np.degrees(p.theta_rad), p.r_mm - s.ls.radius_mm
        k = np.clip(np.digitize(th, edges) - 1, 0, nb - 1)
        cnt = np.bincount(k, minlength=nb)
        row = np.bincount(k, dev, minlength=nb) / np.maximum(cnt, 1)
        row[cnt == 0] = np.nan
        rows.append(row)
    M = 1e3 * np.array(rows)
    z = np.array([s.z_mm for s in ins.sections])
    fig = _figure(7.5, 3.8)
    ax = fig.add_subplot()
    lim = float(np.nanmax(np.abs(M))) if np.isfinite(M).any() else 1.0
    if len(z) > 1:
        o = np.argsort(z)
        zc = z[o]
        ze = np.concatenate([[zc[0] - (zc[1] - zc[0]) / 2], (zc[1:] + zc[:-1]) / 2,
                             [zc[-1] + (zc[-1] - zc[-2]) / 2]])
        im = ax.pcolormesh(edges, ze, M[o], cmap="RdBu_r", vmin=-lim, vmax=lim, shading="flat")
    else:
        im = ax.pcolormesh(edges, [z[0] - 0.5, z[0] + 0.5], M, cmap="RdBu_r", vmin=-lim,
                           vmax=lim)
    fig.colorbar(im, ax=ax, label="deviation (µm)")
    ax.set_xlabel("θ about the LS centre (deg)")
    ax.set_ylabel("z (mm)")
    ax.set_title("deviation from the " + ("nominal" if ins.deviations_mm else "LS circle")
                 + " over θ × z (blank: no valid point)", fontsize=9)
    return _png(fig)


def _fig_harmonics(ins: Inspection, k: int) -> bytes:
    s = ins.sections[k]
    h = s.harmonics
    fig = _figure(7.0, 3.2)
    fig.subplots_adjust(bottom=0.18)  # room for the x label
    ax = fig.add_subplot()
    ax.bar(h.orders, 1e3 * h.amplitude_mm, color="tab:blue", width=0.7)
    u = ins.data["sections"][k]["harmonics"]["u_amplitude_mm"]
    ax.axhline(2e3 * u, color="tab:orange", lw=1, ls="--", label="U(k = 2) of one amplitude")
    ax.set_xlabel("order (undulations per revolution)")
    ax.set_ylabel("amplitude (µm)")
    ax.legend(fontsize=7)
    ax.set_title(f"harmonics of section {s.index} (z = {s.z_mm:.2f} mm)", fontsize=9)
    return _png(fig)


def _fmt(q, scale=1.0, nd=4):
    if isinstance(q, dict):
        if q.get("value") is None:
            return "—"
        return f"{scale * q['value']:.{nd}f} ± {scale * q['U_k2']:.{nd}f}"
    if q is None:
        return "—"
    if isinstance(q, float):
        return f"{scale * q:.{nd}f}"
    return html.escape(str(q))


def _table(header, rows) -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in header)
    b = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{b}</tbody></table>"


def _banner(data: dict) -> str:
    """The verdict first: PASS or FAIL (and what failed), or that no tolerance was given."""
    v = data.get("verdict")
    if v is None:
        return ('<div class="verdict none" id="verdict">NO VERDICT: no tolerance given '
                '(--diameter-mm, --ovality-max-mm, --tolerance-mm)</div>')
    if v["pass"]:
        return '<div class="verdict pass" id="verdict">PASS</div>'
    failed = ", ".join(html.escape(f) for f in v["failed"][:8])
    more = f" and {len(v['failed']) - 8} more" if len(v["failed"]) > 8 else ""
    return f'<div class="verdict fail" id="verdict">FAIL: {failed}{more}</div>'


def _html(data: dict, figs: dict[str, bytes]) -> str:
    """The self-contained ``report.html`` of the inspection ``data`` (as
    :func:`lts360.inspect.run.inspect_cloud` makes it) with the figures ``figs`` (name →
    PNG bytes) inlined as base64: verdict, about, scan summary, events, sections, warnings,
    gaps and figures, in that order."""
    head, body = _section_table(data["sections"])
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'>"
            "<meta name='viewport' content='width=device-width'><title>lts360 inspection</title>"
            f"<style>{_STYLE}</style></head><body>" + _banner(data)
            + f"<h1>Inspection of {html.escape(data['source'])}</h1>"
            + _table(["", ""], _about_rows(data)).replace("<table>", "<table class='kv'>", 1)
            .replace("<thead><tr><th></th><th></th></tr></thead>", "", 1)
            + "<p>Values ± U(k = 2); lengths in mm unless stated. Roundness RONt against the"
            " ISO 12181 reference circles LSCI, MZCI, MCCI, MICI. Ovality Δ/Σ = (Dmax − Dmin)/"
            "(Dmax + Dmin), Δ/D̄ = (Dmax − Dmin)/D_mean. The U of D min, D max, ovality and "
            "RONt includes the noise bias of the extremes (not corrected).</p><h2>Scan</h2>"
            + _table(["quantity", "value"], _summary_rows(data)).replace(
                "<table>", "<table class='kv' id='scan'>", 1)
            + "<h2>Lumps and neck-downs</h2><div class='wide'>" + _events_html(data) + "</div>"
            + "<h2>Sections</h2><div class='wide'>" + _table(head, body) + "</div>"
            + _warnings_html(data["sections"])
            + "<h2>Gaps (no valid point)</h2>" + _gaps_html(data["sections"])
            + "<h2>Figures</h2>" + _figures_html(figs) + "</body></html>")


_STYLE = ("body{font-family:sans-serif;margin:1em;font-size:13px;max-width:100%}"
          "table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #bbb;"
          "padding:2px 6px;text-align:right;overflow-wrap:anywhere}th{background:#eee}"
          "table.kv{max-width:100%}table.kv td:first-child{text-align:left;overflow-wrap:normal;"
          "min-width:9em}"
          "table.kv td:last-child{text-align:left}"
          "div.wide{max-width:100%;overflow-x:auto}"
          ".verdict{font-size:28px;font-weight:bold;padding:.4em .6em;margin:.3em 0 .8em;"
          "overflow-wrap:anywhere}.pass{background:#1b7f2a;color:#fff}"
          ".fail{background:#b3141b;color:#fff}.none{background:#ddd;color:#000}"
          "figure{display:inline-block;margin:.5em;max-width:100%}img{max-width:100%}"
          "h1{font-size:18px;overflow-wrap:anywhere}code{white-space:pre-wrap}")


def _about_rows(data: dict) -> list[tuple[str, str]]:
    """The report's "about" table as (label, HTML) rows: tool, date, command, calibration,
    filter and the extremes' note."""
    st = data["settings"]
    tool = data.get("tool") or {}
    return [("tool", html.escape(f"{tool.get('name', 'lts360')} {tool.get('version', '')}")),
            ("date (UTC)", html.escape(str(data.get("date_utc") or "—"))),
            ("command", f"<code>{html.escape(str(data.get('command') or '—'))}</code>"),
            ("calibration", html.escape(str(data.get("calibration") or "not given"))),
            ("filter", html.escape(st.get("filter", "—"))),
            ("extremes", html.escape(st.get("extremes", "—")))]


def _summary_rows(data: dict) -> list[tuple[str, object]]:
    """The scan's summary table as (label, HTML) rows: sections, calibration u, the size and
    ovality limits, the LS diameter and its trend, the axis, the nominal, the truth and the
    verdict, each where the data holds it."""
    scan = data["scan"]
    summary = [("sections", data["n_sections"]),
               ("calibration uncertainty",
                html.escape(data["settings"]["calibration_uncertainty"]))]
    tol = data.get("tolerances")
    if tol:
        summary += _tolerance_rows(tol)
    tr = scan["trends"]["d_ls_mm"]
    summary.append(("mean LS diameter (mm)", _fmt(tr["mean"], nd=5)))
    if tr["slope_per_mm"] is not None:
        summary.append(("LS diameter trend (µm/mm)", _fmt(1e3 * tr["slope_per_mm"], nd=3)))
    if "axis" in scan:
        summary += _axis_rows(scan)
    if data["nominal"]:
        n = data["nominal"]
        summary.append(("nominal", html.escape(n["source"])))
        if "pass" in n:
            summary += [("tolerance band (mm)", f"{n['lower_mm']:+.4f} … {n['upper_mm']:+.4f}"),
                        ("scan", "<b>PASS</b>" if n["pass"] else "<b>FAIL</b>")]
    if data["truth"]:
        summary.append(("truth", html.escape(data["truth"]["object"])))
    if data.get("verdict") is not None:
        v = data["verdict"]
        summary.append(("verdict", "<b>PASS</b>" if v["pass"] else "<b>FAIL</b>"))
    return summary


def _tolerance_rows(tol: dict) -> list[tuple[str, str]]:
    """Summary rows of the data's ``"tolerances"``: the diameter tolerance and the ovality
    limit, each where given."""
    rows = []
    if tol["diameter_mm"]:
        d = tol["diameter_mm"]
        rows.append(("diameter tolerance (mm)", f"{d['nominal_mm']:g} ± {d['tol_mm']:g}"
                     f" (D min ≥ {d['lower_mm']:g}, D max ≤ {d['upper_mm']:g})"))
    if tol["ovality_max_mm"] is not None:
        rows.append(("ovality limit (mm)", f"≤ {tol['ovality_max_mm']:g}"))
    return rows


def _axis_rows(scan: dict) -> list[tuple[str, str]]:
    """Summary rows of a scan with an axis: its tilt (or why it is too short to tell),
    straightness, cylindricity and the dominant wavelength of the diameter along z."""
    a = scan["axis"]
    tilt = (html.escape(a["note"]) if a.get("note") else
            f"{a['tilt_deg']:.4f} ± {a['U_tilt_deg']:.4f}" if "U_tilt_deg" in a
            else _fmt(a["tilt_deg"], nd=4))
    spec = scan["diameter_spectrum"]
    wl = (html.escape(spec["note"]) if spec.get("note") else
          _fmt(spec["dominant_wavelength_mm"], nd=2))
    return [("axis tilt (deg)", tilt),
            ("straightness of the centres (mm)", _fmt(a["straightness_mm"])),
            ("cylindricity CYLt about the centres' axis (mm)",
             _fmt(scan["cylindricity"]["cylt_mm"])),
            ("dominant wavelength of D along z (mm)", wl)]


def _section_table(sections: list[dict]) -> tuple[list[str], list[list]]:
    """The sections table's header and rows (one per section); the nominal, tolerance and
    truth columns only where some section has them."""
    has_nom = any("nominal" in s for s in sections)
    has_checks = any(s.get("checks") for s in sections)
    has_truth = any(s.get("truth") for s in sections)
    head = ["#", "z (mm)", "cov. (°)", "D LS (mm)", "D min (mm)", "D max (mm)",
            "ovality (mm)", "ovality Δ/Σ (%)", "ovality Δ/D̄ (%)"] + \
        [f"RONt {r} (µm)" for r in REFERENCES] + ["A₃ (µm)"]
    if has_nom:
        head += ["dev. min (µm)", "dev. max (µm)", "result"]
    if has_checks:
        head += ["tolerances"]
    if has_truth:
        head += ["true D LS", "true ovality", "true RONt MZ (µm)", "true A₃ (µm)"]
    body = [_section_cells(s, has_nom=has_nom, has_checks=has_checks, has_truth=has_truth)
            for s in sections]
    return head, body


def _section_cells(s: dict, *, has_nom: bool, has_checks: bool, has_truth: bool) -> list:
    """One section's row of the sections table (cells as HTML), with the nominal, tolerance
    and truth columns where asked for."""
    r = [s["index"], f"{s['z_mm']:.2f}", f"{s['coverage_deg']:.1f}", _fmt(s["d_ls_mm"]),
         _fmt(s["d_min_mm"]), _fmt(s["d_max_mm"]), _fmt(s["ovality_mm"]),
         _fmt(s["ovality_over_sum_pct"], nd=3), _fmt(s["ovality_over_mean_pct"], nd=3)]
    r += [_fmt(s["ront_mm"][ref], 1e3, 1) for ref in REFERENCES]
    r += [_fmt(s["harmonics"]["a3_mm"], 1e3, 1)]
    if has_nom:
        n = s.get("nominal", {})
        r += [_fmt(n.get("deviation_min_mm"), 1e3, 1), _fmt(n.get("deviation_max_mm"), 1e3, 1),
              ("pass" if n.get("pass") else "fail") + f" ({n['conformance_iso14253']})"
              if "pass" in n else "—"]
    if has_checks:
        r += ["; ".join(f"{k}: {'pass' if c['pass'] else 'FAIL'} "
                        f"({c['conformance_iso14253']})"
                        for k, c in s.get("checks", {}).items()) or "—"]
    if has_truth:
        t = s.get("truth") or {}
        r += [_fmt(t.get("d_ls_mm")), _fmt(t.get("ovality_mm")),
              _fmt(None if not t else 1e3 * t["ront_mm"]["MZCI"], nd=1),
              _fmt(None if not t else 1e3 * t["a3_mm"], nd=1)]
    return r


_EVENT_HEAD = ["kind", "z start (mm)", "z end (mm)", "length (mm)", "z extreme (mm)",
               "deviation (µm)", "U(k = 2) (µm)", "P(beyond threshold)"]


def _event_rows(evs: list[dict]) -> list[list[str]]:
    """Rows of an events table, one per lump or neck-down (lengths in mm, deviations in µm)."""
    return [[e["kind"], f"{e['z_start_mm']:.2f}", f"{e['z_end_mm']:.2f}",
             f"{e['length_mm']:.2f}", f"{e['z_extreme_mm']:.2f}",
             f"{1e3 * e['deviation_mm']:+.1f}",
             "—" if e.get("U_k2_mm") is None else f"{1e3 * e['U_k2_mm']:.1f}",
             "—" if e.get("confidence") is None else f"{100 * e['confidence']:.0f} %"]
            for e in evs]


def _events_html(data: dict) -> str:
    """The lumps and neck-downs as HTML: the significant ones' table (or that there is
    none), then those beyond the threshold but within their own U."""
    scan = data["scan"]
    thr = f"{1e3 * data['settings']['lump_threshold_mm']:.0f} µm"
    events = (_table(_EVENT_HEAD, _event_rows(scan["events"])) if scan["events"]
              else f"<p>none significant beyond the threshold of {thr}</p>")
    if scan.get("events_not_significant"):
        events += (f"<p>Beyond {thr} but within what the noise alone gives (not significant, not "
                   "reported as events):</p>"
                   + _table(_EVENT_HEAD, _event_rows(scan["events_not_significant"])))
    return events + _local_events_html(data)


_LOCAL_HEAD = ["kind", "z (mm)", "z span (mm)", "θ (deg)", "arc (deg)", "arc (mm)",
               "depth (µm)", "U(k = 2) (µm)", "z score", "p_noise", "P(beyond threshold)",
               "notes"]


def _local_rows(evs: list[dict]) -> list[list[str]]:
    """Rows of the arc-matched events' table (:mod:`lts360.inspect.local_events`)."""
    return [[e["kind"], f"{e['z_extreme_mm']:.2f}", f"{e['z_start_mm']:.2f} … {e['z_end_mm']:.2f}",
             f"{e['theta_deg']:.1f}", f"{e['arc_start_deg']:.1f} … {e['arc_end_deg']:.1f}",
             f"{e['arc_mm']:.1f}", f"{1e3 * e['depth_mm']:+.1f}", f"{1e3 * e['U_k2_mm']:.1f}",
             f"{e['z_score']:+.1f}", f"{e['p_noise']:.2g}", f"{100 * e['confidence']:.0f} %",
             html.escape("; ".join(e.get("notes", []))) or "—"] for e in evs]


def _local_events_html(data: dict) -> str:
    """The arc-matched lumps and dents as HTML: the detector's settings, the events (or that
    there is none) and those set apart."""
    scan = data["scan"]
    if "local_events_settings" not in scan:
        return ""
    st = scan["local_events_settings"]
    if "critical_z" not in st:
        return f"<p>Local lumps and dents: {html.escape(st.get('note', 'not searched'))}</p>"
    out = (f"<h3>Local lumps and dents (matched to σ = {st['arc_sigma_mm']:g} mm of arc)</h3>"
           f"<p>Each section's profile against the median of the sections farther along z, the "
           f"deviation fitted by a Gaussian bump at every θ; significant where |z| > "
           f"{st['critical_z']:.2f} ({100 * st['false_event_rate']:g} % false-event rate over "
           f"the scan); depth against the reference form.</p>")
    out += (_table(_LOCAL_HEAD, _local_rows(scan["local_events"])) if scan["local_events"]
            else "<p>none significant</p>")
    if scan.get("local_events_set_apart"):
        out += ("<p>Set apart (significant, but below the threshold or the image of a longer "
                "event in the reference):</p>"
                + _table(_LOCAL_HEAD, _local_rows(scan["local_events_set_apart"])))
    return out


def _warnings_html(sections: list[dict]) -> str:
    """The sections' warnings as an HTML list under its heading; empty where there is none."""
    warn = [f"<li>section {s['index']} (z = {s['z_mm']:.2f} mm): {html.escape(w)}</li>"
            for s in sections for w in s.get("warnings", [])]
    return f"<h2>Warnings</h2><ul>{''.join(warn)}</ul>" if warn else ""


def _gaps_html(sections: list[dict]) -> str:
    """The sections' gaps (no valid point) as an HTML table, or ``<p>none</p>``."""
    gaps = [[s["index"], f"{g['start_deg']:.1f}", f"{g['end_deg']:.1f}", f"{g['width_deg']:.1f}",
             html.escape(", ".join(f"{k}: {v}" for k, v in g["flags"].items()))]
            for s in sections for g in s["gaps"]]
    return (_table(["section", "from (°)", "to (°)", "width (°)", "flags"], gaps) if gaps
            else "<p>none</p>")


def _figures_html(figs: dict[str, bytes]) -> str:
    """The figures (name → PNG bytes) as HTML figures with the PNGs inlined as base64."""
    return "".join(f'<figure><img alt="{html.escape(n)}" src="data:image/png;base64,'
                   f'{base64.b64encode(b).decode("ascii")}"><figcaption>{html.escape(n)}'
                   "</figcaption></figure>" for n, b in figs.items())


def write_report(ins: Inspection, out) -> Path:
    """Write the report into the directory ``out`` (replaced as a whole, atomically)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {str(out)!r} exists and is not a directory")
    if not out.parent.exists():
        raise ValueError(f"--out: directory {str(out.parent)!r} does not exist")
    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        (tmp / "inspection.json").write_text(json.dumps(_finite(ins.data), indent=1,
                                                        default=_jsonable, allow_nan=False))
        rows = csv_rows(ins.data)
        cols = list(dict.fromkeys(k for r in rows for k in r))
        with open(tmp / "sections.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols)
            w.writeheader()
            w.writerows(rows)
        k = key_section(ins)
        figs = {"polar_deviation.png": _fig_polar(ins, k), "along_z.png": _fig_along_z(ins),
                "deviation_map.png": _fig_map(ins), "harmonics.png": _fig_harmonics(ins, k)}
        for name, b in figs.items():
            (tmp / name).write_bytes(b)
        (tmp / "report.html").write_text(_html(ins.data, figs), encoding="utf-8")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if out.exists():
        shutil.rmtree(out)
    tmp.replace(out)
    return out


def _finite(value):
    """The data with every NaN or infinity as null (strict JSON)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.ndarray):
        return _finite(value.tolist())
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value)}")
