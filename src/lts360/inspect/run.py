"""Inspect a measured cloud: every section, the scan, the nominal, the uncertainties and the
truth, gathered into one JSON-ready result (units in the names; a quantity with uncertainty is
``{"value", "u", "U_k2"}``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from lts360.inspect import scan as scan_mod
from lts360.inspect.circles import REFERENCES, least_squares_circle
from lts360.inspect.extremes import (
    DEFAULT_EXTREME_DRAWS,
    FILTER_UPR_RANGE,
    default_upr,
    extreme_noise,
)
from lts360.inspect.local_events import DEFAULT_ARC_MM
from lts360.inspect.nominal import Nominal, ToleranceBand, deviations, place_nominal
from lts360.inspect.profile import DEFAULT_BIN_DEG, DEFAULT_GAP_DEG, valid_mask
from lts360.inspect.section import MIN_POINTS, SectionResult, analyse_section
from lts360.inspect.uncertainty import (
    DEFAULT_DRAWS,
    calibration_u,
    combine,
    correlated_mean_u,
    scatter_u,
)
from lts360.recon.triangulation.cloud import VIEW_NAMES, Cloud

__all__ = ["Inspection", "inspect_cloud", "NoValidPoints"]


_VIEW_LOOKUP = np.array([VIEW_NAMES.get(c, "?") for c in range(256)], dtype=object)


class NoValidPoints(ValueError):
    """The cloud holds no section with enough valid points."""


@dataclass
class Inspection:
    """The result: ``data`` (JSON-ready) and what the figures need."""

    data: dict
    sections: list[SectionResult]
    deviations_mm: list = field(default_factory=list)  # per section (n_i,) or None
    reference_radius_mm: list = field(default_factory=list)
    band: ToleranceBand | None = None


def _q(value, *u_parts, bias=None) -> dict:
    """``{value, u, U_k2}``; with the noise ``bias`` of an extreme (not corrected) also
    ``bias_mm`` and ``U_k2 = 2u + |bias|``."""
    v = None if value is None or not np.isfinite(value) else float(value)
    out = {"value": v, **combine(*u_parts)}
    if bias is not None and np.isfinite(bias):
        out["bias_mm"] = float(bias)
        out["U_k2"] = out["U_k2"] + abs(float(bias))
    return out


def _section_dict(s: SectionResult, us: dict, uc: dict | None, u_radial_mm: float,
                  ex=None) -> dict:
    """``ex`` (:class:`lts360.inspect.extremes.ExtremeNoise`): the extremes' u from the
    section's noise (in place of the scatter table's) and their bias, carried in U."""
    g = (uc or {}).get
    if ex is not None:
        us = {**us, "d_min_mm": ex.u_mm["d_min_mm"], "d_max_mm": ex.u_mm["d_max_mm"],
              "ovality_mm": ex.u_mm["ovality_mm"],
              "calliper_min_mm": ex.u_mm["d_min_mm"], "calliper_max_mm": ex.u_mm["d_max_mm"]}
        b = ex.bias_mm
    else:
        us = {**us, "calliper_min_mm": us["calliper_mm"], "calliper_max_mm": us["calliper_mm"]}
        b = {}
    ub = 2.0 * u_radial_mm if u_radial_mm else None  # a common radial offset: 2u on sizes
    d = s.diameters
    ls = s.ls
    out = {"index": s.index, "z_mm": s.z_mm, "n_valid": s.n_valid, "n_samples": s.n_samples,
           "coverage_deg": s.coverage_deg,
           "gaps": [{"start_deg": x.start_deg, "end_deg": x.end_deg, "width_deg": x.width_deg,
                     "flags": x.flags} for x in s.gaps],
           "scatter_mm": s.scatter_mm, "points_per_bin": s.points_per_bin,
           "warnings": s.extra.get("warnings", []),
           "centre_x_mm": _q(ls.centre_mm[0], us["centre_x_mm"], g("centre_x_mm")),
           "centre_y_mm": _q(ls.centre_mm[1], us["centre_y_mm"], g("centre_y_mm")),
           "d_ls_mm": _q(ls.diameter_mm, us["d_ls_mm"], g("d_ls_mm"), ub),
           "d_mean_mm": _q(d.d_mean_mm, us["d_mean_mm"], g("d_mean_mm"), ub),
           "d_min_mm": _q(d.d_min_mm, us["d_min_mm"], g("d_min_mm"), ub,
                          bias=b.get("d_min_mm")),
           "d_max_mm": _q(d.d_max_mm, us["d_max_mm"], g("d_max_mm"), ub,
                          bias=b.get("d_max_mm")),
           "phi_d_min_deg": d.phi_d_min_deg, "phi_d_max_deg": d.phi_d_max_deg,
           "n_directions_measured": d.n_directions_measured,
           "ovality_mm": _q(d.ovality_mm, us["ovality_mm"], g("ovality_mm"),
                            bias=b.get("ovality_mm")),
           "calliper_min_mm": _q(d.calliper_min_mm, us["calliper_min_mm"], g("d_min_mm"), ub,
                                 bias=b.get("d_min_mm")),
           "calliper_max_mm": _q(d.calliper_max_mm, us["calliper_max_mm"], g("d_max_mm"), ub,
                                 bias=b.get("d_max_mm"))}
    uo = out["ovality_mm"]["U_k2"] / 2
    if np.isfinite(d.ovality_mm):
        out["ovality_over_sum_pct"] = _q(d.ovality_over_sum_pct,
                                         100 * uo / (d.d_max_mm + d.d_min_mm))
        out["ovality_over_mean_pct"] = _q(d.ovality_over_mean_pct, 100 * uo / d.d_mean_mm)
    else:
        out["ovality_over_sum_pct"] = out["ovality_over_mean_pct"] = _q(None)
    und = s.extra.get("undetermined", [])
    out["ront_mm"] = {name: _q(None if name in und else c.ront_mm, ex.u_mm[f"ront_{name}_mm"] if ex is not None
                               else us["ront_mm"], g("ront_lsci_mm"),
                               bias=b.get(f"ront_{name}_mm"))
                      for name, c in s.circles.items()}
    out["reference_circles"] = {
        name: {"centre_x_mm": float(c.centre_mm[0]), "centre_y_mm": float(c.centre_mm[1]),
               "diameter_mm": _q(None if name in und else c.diameter_mm,
                                 us["d_ls_mm"] if name == "LSCI"
                                 else us["size_ref_mm"], g("d_ls_mm"), ub)}
        for name, c in s.circles.items()}
    h = s.harmonics
    k_dom, a_dom = h.dominant()
    out["harmonics"] = {"amplitude_mm": h.amplitude_mm.tolist(), "phase_deg": h.phase_deg.tolist(),
                        "u_amplitude_mm": combine(us["harmonic_mm"])["u"],
                        "a2_mm": _q(h.amplitude(2), us["harmonic_mm"], g("a2_mm")),
                        "a3_mm": _q(h.amplitude(3), us["harmonic_mm"], g("a3_mm")),
                        "dominant_order": k_dom, "dominant_amplitude_mm": a_dom}
    return out


def _truth_rows(truth, sections: list[SectionResult],
                filter_upr: float | None = None) -> tuple[dict, list]:
    from lts360.inspect.truth import load_truth, true_section_xy

    obj, _ = truth if isinstance(truth, tuple) else load_truth(truth)
    rows = []
    for s in sections:
        xy = true_section_xy(obj, s.z_mm)
        if xy is None or len(xy) < MIN_POINTS:
            rows.append(None)
            continue
        t = analyse_section(xy, index=s.index, z_mm=s.z_mm, filter_upr=filter_upr)
        rows.append({"centre_x_mm": float(t.ls.centre_mm[0]),
                     "centre_y_mm": float(t.ls.centre_mm[1]), "d_ls_mm": t.ls.diameter_mm,
                     "d_mean_mm": t.diameters.d_mean_mm, "d_min_mm": t.diameters.d_min_mm,
                     "d_max_mm": t.diameters.d_max_mm, "ovality_mm": t.diameters.ovality_mm,
                     "ront_mm": {k: c.ront_mm for k, c in t.circles.items()},
                     "a2_mm": t.harmonics.amplitude(2),
                     "a3_mm": t.harmonics.amplitude(3)})
    return {"object": obj.spec, "analytic": obj.radius_fn is not None}, rows


def inspect_cloud(cloud: Cloud, *, nominal: Nominal | None = None,
                  band: ToleranceBand | None = None, calibration=None, truth=None,
                  lump_threshold_mm: float = scan_mod.DEFAULT_LUMP_MM,
                  n_draws: int = DEFAULT_DRAWS, seed: int = 0, u_radial_mm: float = 0.0,
                  bin_deg: float = DEFAULT_BIN_DEG, gap_deg: float = DEFAULT_GAP_DEG,
                  filter_upr: float | None = None, use_filter: bool = True,
                  extreme_draws: int = DEFAULT_EXTREME_DRAWS, diameter_tol=None,
                  ovality_max_mm: float | None = None, lump_arc_mm: float = DEFAULT_ARC_MM,
                  source: str = "") -> Inspection:
    """Inspect every section of ``cloud``.

    Parameters
    ----------
    cloud : Cloud
        As ``lts360 measure`` writes it; z of a section is its stage position.
    nominal : Nominal, optional
    band : ToleranceBand, optional
        Needs ``nominal``.
    calibration : Calibration, optional
        The one the cloud was measured with; its covariance gives the calibration u.
    truth : path or (SceneObject, z list), optional
        A rendered frame or scan: true values beside the measured ones.
    u_radial_mm : float, >= 0
        Type-B standard uncertainty of a radial offset common to a section (the rig's error
        budget or a reference measurement's bias): 2u on every diameter, u on a deviation,
        nothing on centre, ovality, roundness or harmonics, where it cancels.
    filter_upr : float, [1, 1000], optional
        Cut-off of the ISO 12181-2 Gaussian filter applied before the reference circles and
        diameters; default: the cut-off for the scan's median LS diameter
        (:func:`lts360.inspect.extremes.default_upr`).
    use_filter : bool
        False: no filter (``--filter none``).
    extreme_draws : int, >= 2
        Noise draws of each section's extremes' Monte Carlo (:mod:`lts360.inspect.extremes`).
    diameter_tol : DiameterTolerance, optional
    ovality_max_mm : float, > 0, optional
        Size and ovality limits (:mod:`lts360.inspect.tolerances`); with them, or with
        ``band``, ``data["verdict"]`` holds the scan's PASS/FAIL.
    lump_arc_mm : float, > 0
        σ (mm of arc) of the lumps and dents the arc-matched detector looks for
        (:mod:`lts360.inspect.local_events`).

    Raises
    ------
    NoValidPoints
        No section has :data:`MIN_POINTS` valid points.
    """
    _check_arguments(u_radial_mm=u_radial_mm, filter_upr=filter_upr, band=band,
                     nominal=nominal, use_filter=use_filter, lump_arc_mm=lump_arc_mm)
    ok = _valid_mask(cloud, source)
    form_upr = _form_upr(cloud, ok)
    filter_upr, filter_note = _filter_setting(use_filter, filter_upr, form_upr)
    sections, skipped, xy_list, view_list, times = _analyse_sections(
        cloud, ok, bin_deg=bin_deg, gap_deg=gap_deg, filter_upr=filter_upr)
    u_cal, cal_note = _calibration_u(calibration, xy_list, view_list, n_draws=n_draws,
                                     seed=seed)
    exs = _extreme_noises(sections, bin_deg=bin_deg, gap_deg=gap_deg, filter_upr=filter_upr,
                          extreme_draws=extreme_draws, seed=seed)
    rows = _section_rows(sections, exs, u_cal, u_radial_mm, times)
    inspection = Inspection(data={}, sections=sections, band=band)
    nom_out = None
    if nominal is not None:
        nom_out = _against_nominal(inspection, rows, nominal, band, u_cal, u_radial_mm)
    tol_out = _tolerances(rows, diameter_tol, ovality_max_mm)
    verdict = _verdict(rows, nom_out, tol_out)
    truth_out = None
    if truth is not None:
        truth_out, trows = _truth_rows(truth, sections, filter_upr)
        for row, t in zip(rows, trows):
            row["truth"] = t
    settings = _settings(bin_deg=bin_deg, gap_deg=gap_deg, filter_upr=filter_upr,
                         filter_note=filter_note, extreme_draws=extreme_draws,
                         lump_threshold_mm=lump_threshold_mm, cal_note=cal_note,
                         u_radial_mm=u_radial_mm)
    inspection.data = {
        "tool": {"name": "lts360", "version": _tool_version()},
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "source": source, "n_sections": len(sections), "sections_skipped": skipped,
        "units": "lengths in mm, angles in deg; {value, u, U_k2}: U_k2 = 2u",
        "settings": settings,
        "sections": rows, "scan": _scan(sections, rows, lump_threshold_mm, lump_arc_mm),
        "nominal": nom_out, "tolerances": tol_out, "verdict": verdict, "truth": truth_out}
    return inspection


def _check_arguments(*, u_radial_mm: float, filter_upr: float | None,
                     band: ToleranceBand | None, nominal: Nominal | None,
                     use_filter: bool, lump_arc_mm: float = DEFAULT_ARC_MM) -> None:
    """Refuse contradictory or out-of-range options (:class:`ValueError`, worded for the
    command line); returns nothing."""
    if not (u_radial_mm >= 0 and np.isfinite(u_radial_mm)):
        raise ValueError(f"--u-radial-mm: must be >= 0, got {u_radial_mm}")
    lo, hi = FILTER_UPR_RANGE
    if filter_upr is not None and not (np.isfinite(filter_upr) and lo <= filter_upr <= hi):
        raise ValueError(f"--filter-upr: must be in [{lo:g}, {hi:g}], got {filter_upr}")
    if band is not None and nominal is None:
        raise ValueError("--tolerance-mm/--upper-mm/--lower-mm need --nominal")
    if not use_filter and filter_upr is not None:
        raise ValueError("--filter-upr: give it or --filter none, not both")
    if not (np.isfinite(lump_arc_mm) and lump_arc_mm > 0):
        raise ValueError(f"--lump-arc-mm: must be > 0, got {lump_arc_mm}")


def _valid_mask(cloud: Cloud, source: str) -> np.ndarray:
    """The cloud's valid points (finite, quality FOUND or SATURATED) as a boolean mask over
    its samples; raises :class:`NoValidPoints` where there is none."""
    ok = valid_mask(cloud.points_mm, cloud.quality)
    if not ok.any():
        raise NoValidPoints(f"the cloud {source or ''} has no valid point ({len(cloud)} samples, "
                            "none finite with quality FOUND or SATURATED)".replace("  ", " "))
    return ok


def _form_upr(cloud: Cloud, ok: np.ndarray) -> float | None:
    """The default filter cut-off (UPR) for the scan's median LS diameter, from
    the unfiltered valid points of every section with :data:`MIN_POINTS` of them; ``None``
    where no section has that many."""
    diameters = []
    for k in np.unique(cloud.section):
        m = (cloud.section == k) & ok
        if m.sum() >= MIN_POINTS:
            diameters.append(least_squares_circle(cloud.points_mm[m, :2]).diameter_mm)
    return default_upr(float(np.median(diameters))) if diameters else None


def _filter_setting(use_filter: bool, filter_upr: float | None,
                    form_upr: float | None) -> tuple[float | None, str]:
    """The filter cut-off to apply (``None``: no filter) and its note for the report, from
    the options and the scan's default ``form_upr``."""
    if use_filter and filter_upr is None:
        return form_upr, (f"ISO 12181-2 Gaussian, {form_upr:g} UPR (the default for the "
                          "scan's diameter; the diameter table is not verified against the "
                          "standard's text)")
    if use_filter:
        return filter_upr, f"ISO 12181-2 Gaussian, {filter_upr:g} UPR (--filter-upr)"
    return None, "none (--filter none)"


def _analyse_sections(cloud: Cloud, ok: np.ndarray, *, bin_deg: float, gap_deg: float,
                      filter_upr: float | None) -> tuple[list, list, list, list, list]:
    """Analyse each section of the cloud with :data:`MIN_POINTS` valid points.

    Returns the :class:`SectionResult` list, the skipped sections (``{index, z_mm,
    n_valid}``), and per analysed section its valid xy (mm), their views' names and its
    exposure time (:func:`_section_time`). Raises :class:`NoValidPoints` where none is
    analysed.
    """
    sections, skipped, xy_list, view_list, times = [], [], [], [], []
    for k in np.unique(cloud.section):
        m = cloud.section == k
        v = m & ok
        z = float(np.median(cloud.points_mm[m, 2][np.isfinite(cloud.points_mm[m, 2])])) \
            if np.isfinite(cloud.points_mm[m, 2]).any() else float("nan")
        if v.sum() < MIN_POINTS:
            skipped.append({"index": int(k), "z_mm": z, "n_valid": int(v.sum())})
            continue
        inv = m & ~ok
        sections.append(analyse_section(
            cloud.points_mm[v, :2], index=int(k), z_mm=z, theta_valid_rad=cloud.theta_rad[v],
            theta_invalid_rad=cloud.theta_rad[inv], quality_invalid=cloud.quality[inv],
            bin_deg=bin_deg, gap_deg=gap_deg, filter_upr=filter_upr))
        xy_list.append(cloud.points_mm[v, :2])
        view_list.append(_VIEW_LOOKUP[cloud.view[v]])
        times.append(_section_time(cloud, v))
    if not sections:
        raise NoValidPoints(f"no section has {MIN_POINTS} valid points: "
                            + ", ".join(f"section {s['index']}: {s['n_valid']}" for s in skipped))
    return sections, skipped, xy_list, view_list, times


def _calibration_u(calibration, xy_list: list, view_list: list, *, n_draws: int,
                   seed: int) -> tuple[list | None, str]:
    """Each section's calibration uncertainties (a dict per section; ``None`` without a
    calibration or its covariance) and how they were found, as the report words it."""
    if calibration is None:
        return None, "not given"
    u_cal = calibration_u(xy_list, view_list, calibration, n_draws=n_draws, seed=seed)
    return u_cal, (f"Monte Carlo over {n_draws} calibration draws (seed {seed})"
                   if u_cal is not None else "the calibration carries no covariance: 0")


def _extreme_noises(sections: list[SectionResult], *, bin_deg: float, gap_deg: float,
                    filter_upr: float | None, extreme_draws: int, seed: int) -> list[tuple]:
    """Per section ``(ExtremeNoise, scatter u table, correlation length in bins)``: the noise
    of its extremes from a Monte Carlo of its own unfiltered profile's noise."""
    exs = []
    for s in sections:
        raw = s.extra.get("raw_profile", s.profile)  # unfiltered
        u_mean, tau, s_bin = correlated_mean_u(raw.theta_rad, raw.r_mm, s.ls.radius_mm,
                                               bin_deg=bin_deg)
        us = scatter_u(s.scatter_mm, s.n_valid, s.points_per_bin, u_mean_radius_mm=u_mean,
                       u_bin_mm=s_bin)
        bin_u = max(s.scatter_mm / np.sqrt(max(s.points_per_bin, 1.0)),
                    s_bin if np.isfinite(s_bin) else 0.0)
        rho = (tau - 1) / (tau + 1) if np.isfinite(tau) else 0.0
        ex = extreme_noise(raw, upr=filter_upr, s_bin_mm=bin_u, rho=rho, n_draws=extreme_draws,
                           rng=np.random.SeedSequence([seed, int(s.index)]), gap_deg=gap_deg)
        exs.append((ex, us, tau))
    return exs


def _section_rows(sections: list[SectionResult], exs: list[tuple], u_cal: list | None,
                  u_radial_mm: float, times: list) -> list[dict]:
    """The JSON rows of the sections (:func:`_section_dict`), each with its extremes' noise,
    its correlation length and, for a moving object, its time."""
    rows = []
    for i, (s, (ex, us, tau)) in enumerate(zip(sections, exs)):
        row = _section_dict(s, us, None if u_cal is None else u_cal[i], u_radial_mm, ex)
        row["extreme_noise"] = {"s_bin_mm": ex.s_bin_mm, "rho": ex.rho, "n_draws": ex.n_draws,
                                "bias_mm": ex.bias_mm, "u_mm": ex.u_mm}
        row["correlation_bins"] = tau if np.isfinite(tau) else None
        if times[i] is not None:
            row["time_s"], row["time_span_s"] = times[i]
        rows.append(row)
    return rows


def _against_nominal(inspection: Inspection, rows: list[dict], nominal: Nominal,
                     band: ToleranceBand | None, u_cal: list | None,
                     u_radial_mm: float) -> dict:
    """Compare each section with the nominal placed on its LS centre: appends ``(ring,
    deviations)`` to ``inspection.deviations_mm``, sets each row's ``"nominal"``
    (:func:`_nominal_row`) and returns the scan's ``"nominal"`` entry (with ``band``, its
    limits and pass)."""
    all_pass = True
    for i, (s, row) in enumerate(zip(inspection.sections, rows)):
        ring = place_nominal(nominal.contour(s.z_mm), s.ls.centre_mm)
        dev = deviations(s.xy_mm, ring)
        inspection.deviations_mm.append((ring, dev))
        u_dev = combine(scatter_u(s.scatter_mm, 1, 1)["deviation_mm"],
                        None if u_cal is None else u_cal[i]["d_ls_mm"] / 2,
                        u_radial_mm or None)
        row["nominal"] = _nominal_row(dev, u_dev, band)
        if band is not None:
            all_pass &= row["nominal"]["pass"]
    nom_out = {"source": nominal.source, "alignment": "LS centre onto LS centre",
               "round": nominal.is_round}
    if band is not None:
        nom_out.update({"upper_mm": band.upper_mm, "lower_mm": band.lower_mm,
                        "pass": bool(all_pass)})
    return nom_out


def _nominal_row(dev: np.ndarray, u_dev: dict, band: ToleranceBand | None) -> dict:
    """One section's ``"nominal"`` entry from its deviations (mm) and their ``u_dev``
    (``{u, U_k2}``): the extreme and RMS deviations and, with ``band``, the points outside,
    pass and the ISO 14253-1 conformance."""
    nd = {"deviation_min_mm": _q(dev.min(), u_dev["u"]),
          "deviation_max_mm": _q(dev.max(), u_dev["u"]),
          "deviation_rms_mm": float(np.sqrt(np.mean(dev**2)))}
    if band is not None:
        outside = (dev > band.upper_mm) | (dev < band.lower_mm)
        U = u_dev["U_k2"]
        sure_in = (dev.max() <= band.upper_mm - U) and (dev.min() >= band.lower_mm + U)
        sure_out = (dev.max() > band.upper_mm + U) or (dev.min() < band.lower_mm - U)
        nd.update({"n_outside": int(outside.sum()), "pass": bool(not outside.any()),
                   "conformance_iso14253": "conforms" if sure_in else
                   ("does not conform" if sure_out else "inconclusive")})
    return nd


def _tolerances(rows: list[dict], diameter_tol, ovality_max_mm: float | None) -> dict | None:
    """With a size or ovality limit: sets each row's ``"checks"``
    (:func:`lts360.inspect.tolerances.section_checks`) and returns the scan's
    ``"tolerances"`` entry; ``None`` without either."""
    if diameter_tol is None and ovality_max_mm is None:
        return None
    from lts360.inspect.tolerances import section_checks

    for row in rows:
        row["checks"] = section_checks(row, diameter=diameter_tol,
                                       ovality_max_mm=ovality_max_mm)
    return {"diameter_mm": None if diameter_tol is None else
            {"nominal_mm": diameter_tol.nominal_mm, "tol_mm": diameter_tol.tol_mm,
             "lower_mm": diameter_tol.lower_mm, "upper_mm": diameter_tol.upper_mm},
            "ovality_max_mm": ovality_max_mm,
            "rule": "pass: the measured values within the limits; conformance by "
                    "ISO 14253-1 with U(k = 2)"}


def _verdict(rows: list[dict], nom_out: dict | None, tol_out: dict | None) -> dict | None:
    """The scan's PASS/FAIL (``{pass, failed}``: the profile zone and each failed check with
    its z) where a tolerance was given; ``None`` where none was."""
    if tol_out is None and (nom_out is None or "pass" not in nom_out):
        return None
    failed = []
    if nom_out is not None and "pass" in nom_out and not nom_out["pass"]:
        failed.append("profile zone")
    for row in rows:
        for name, c in row.get("checks", {}).items():
            if not c["pass"]:
                failed.append(f"{name} at z = {row['z_mm']:.2f} mm")
    return {"pass": not failed, "failed": failed}


def _tool_version() -> str:
    """The installed lts360's version; ``"0+unknown"`` when run from a source tree."""
    try:
        return version("lts360")
    except PackageNotFoundError:  # run from a source tree
        return "0+unknown"


def _settings(*, bin_deg: float, gap_deg: float, filter_upr: float | None, filter_note: str,
              extreme_draws: int, lump_threshold_mm: float, cal_note: str,
              u_radial_mm: float) -> dict:
    """The ``"settings"`` entry: the options the inspection ran with, and the notes on the
    filter, the extremes' uncertainty and the calibration uncertainty."""
    return {"bin_deg": bin_deg, "gap_deg": gap_deg, "filter_upr": filter_upr,
            "filter": filter_note,
            "extremes": f"D min, D max, ovality, RONt: U(k = 2) = 2u + |bias|, the "
                        f"noise bias of the extremes from a Monte Carlo of "
                        f"{extreme_draws} draws of each section's own noise, not "
                        f"corrected",
            "lump_threshold_mm": lump_threshold_mm,
            "reference_circles": list(REFERENCES),
            "calibration_uncertainty": cal_note,
            "u_radial_mm": u_radial_mm}


def _section_time(cloud: Cloud, valid: np.ndarray) -> tuple[float, float] | None:
    """A moving object's section: the median exposure time of its valid points' rows and
    their spread (a rolling shutter exposes its views at different times); ``None`` for a
    still cloud."""
    if cloud.time_s is None:
        return None
    t = np.asarray(cloud.time_s)[valid]
    t = t[np.isfinite(t)]
    if t.size == 0:
        return None
    return float(np.median(t)), float(np.ptp(t))


def _local(sections: list[SectionResult], rows: list[dict], lump_mm: float,
           arc_mm: float) -> dict:
    """The arc-matched lumps and dents (:mod:`lts360.inspect.local_events`) from each
    section's unfiltered profile and its bins' noise: ``local_events`` (significant, able to
    reach the threshold), ``local_events_set_apart`` and ``local_events_settings``."""
    from lts360.inspect.local_events import local_events
    from lts360.inspect.profile import uniform_profile

    grid = np.array([uniform_profile(s.extra.get("raw_profile", s.profile))[1]
                     for s in sections])
    ev, apart, info = local_events(
        [s.z_mm for s in sections], grid, [r["extreme_noise"]["s_bin_mm"] for r in rows],
        [r["extreme_noise"]["rho"] for r in rows],
        float(np.median([s.ls.radius_mm for s in sections])),
        indices=[s.index for s in sections], arc_mm=arc_mm, threshold_mm=lump_mm,
        rate=scan_mod.FALSE_EVENT_RATE / 2)
    return {"local_events": [e.__dict__ for e in ev],
            "local_events_set_apart": [e.__dict__ for e in apart],
            "local_events_settings": info}


def _scan(sections: list[SectionResult], rows: list[dict], lump_mm: float,
          lump_arc_mm: float = DEFAULT_ARC_MM) -> dict:
    z = np.array([s.z_mm for s in sections])
    val = lambda key: np.array([r[key]["value"] if r[key]["value"] is not None else np.nan  # noqa: E731
                                for r in rows], dtype=float)
    out = {"n_sections": len(sections),
           "z_range_mm": [float(z.min()), float(z.max())],
           "trends": {k: scan_mod.trend(z, val(k)) for k in
                      ("d_ls_mm", "d_min_mm", "d_max_mm", "ovality_mm", "centre_x_mm",
                       "centre_y_mm")},
           }
    un = [r.get("extreme_noise", {}).get("u_mm", {}) for r in rows]
    # each section's D min and D max less its own noise bias: the bias depends on the shape at
    # the extreme (a dent's narrow minimum is pushed down less than the flat minimum of a
    # smooth section), so it does not cancel against the scan's median
    unbiased = {k: val(k) - np.array([r[k].get("bias_mm", 0.0) for r in rows])
                for k in ("d_min_mm", "d_max_mm")}
    ev = scan_mod.lumps_and_necks(
        z, unbiased["d_min_mm"], unbiased["d_max_mm"], threshold_mm=lump_mm,
        indices=[s.index for s in sections],
        u_d_min_mm=[x.get("d_min_mm", np.nan) for x in un] if all(un) else None,
        u_d_max_mm=[x.get("d_max_mm", np.nan) for x in un] if all(un) else None)
    out["events"] = [e.__dict__ for e in ev if e.significant]
    out["events_not_significant"] = [e.__dict__ for e in ev if not e.significant]
    out.update(_local(sections, rows, lump_mm, lump_arc_mm))
    if all("time_s" in r for r in rows):  # a moving object: when each event passed the laser
        t = np.array([r["time_s"] for r in rows])
        order = np.argsort(z)
        out["time_range_s"] = [float(t.min()), float(t.max())]
        for e in out["events"]:
            e["time_s"] = float(np.interp(e["z_extreme_mm"], z[order], t[order]))
    if len(sections) >= 2 and np.ptp(z) > 0:
        ax = scan_mod.fit_axis(z, [s.ls.centre_mm for s in sections])
        u_c = float(np.median([np.hypot(r["centre_x_mm"]["u"], r["centre_y_mm"]["u"])
                               / np.sqrt(2) for r in rows]))
        tu = scan_mod.tilt_uncertainty(z, ax, u_c)
        out["axis"] = {"x0_mm": ax.x0_mm, "y0_mm": ax.y0_mm, "slope_x": ax.slope_x,
                       "slope_y": ax.slope_y,
                       "tilt_deg": None if tu["too_short"] else ax.tilt_deg,
                       "U_tilt_deg": tu["U_tilt_deg"],
                       "tilt_azimuth_deg": None if tu["too_short"] else ax.tilt_azimuth_deg,
                       "straightness_mm": ax.straightness_mm}
        if tu["too_short"]:
            out["axis"]["note"] = (f"too short to tell: the tilt's U(k = 2) is "
                                   f"{tu['U_tilt_deg']:.3f}° > {scan_mod.TILT_TELL_DEG}° "
                                   f"(the centres give {ax.tilt_deg:.3f}°)")
        out["cylindricity"] = scan_mod.cylindricity(z, [s.profile.xy_mm for s in sections],
                                                    start=ax)
        out["diameter_spectrum"] = scan_mod.diameter_spectrum(z, val("d_ls_mm"))
    return out
