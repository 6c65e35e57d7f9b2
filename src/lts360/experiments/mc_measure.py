"""How a Monte Carlo trial measures its image: the placements' stored renders, the §4.4
compensation (and mastering) of the nominal and the drawn calibrations at the reference
placement, one inverse plan and one sampling of the image for the configurations of a draw,
and the twin's correction, rendered for the trial or frozen per placement
(:mod:`lts360.experiments.monte_carlo` draws the trials and runs the study).

The twin's correction of a section is its line-centre bias: the twin image of the measured
section, rendered noise-free and measured as the image was, minus the section itself
(:class:`lts360.twin.TwinCorrector`).  ``twin_per="trial"`` renders it for every trial, from
the trial's noisy section, with the trial's drawn calibration — what a user's measurement
does, and about 0.3 s of a trial's 0.63 s of CPU (two corrections: the image and the
master's reference shot, each rendered on ~12 700 pixels at 64 spp).
``twin_per="placement"`` computes each placement's correction once per process, from its
noise-free image measured with the nominal calibration, and subtracts it from every trial of
that placement (per view and ray of the grid; a point the frozen correction does not cover
stays uncorrected, as the twin leaves one).  What that leaves out is how the correction moves
with the trial's draw — its calibration, noise and speckle — which the paired benchmark
measures (``benchmarks/bench_mc_twin.py``, BENCHMARKS.md): a small fraction of u(y), and a
trial costs a quarter.

A trial's two noisy images (its own and the reference shot) get their speckle and sensor noise
on the pixels the trial's plan reads alone (:func:`read_set`, ~1 % of the frame; the others
noise-free): the measurement reads nothing else, so it is the full frame's in distribution
(the speckle there is the full frame's, bit for bit).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np

from lts360.experiments.gauge_study import DEFAULT_PLACEMENT_MM, GAUGE_DIAMETER_MM
from lts360.folders import read_frame_meta

__all__ = ["TWIN_PER", "frozen_image_bias", "frozen_reference_bias", "apply_bias",
           "stored_render", "read_set", "reads_within", "READ_MARGIN_PX"]

#: Where a Monte Carlo trial's twin correction comes from (module docstring).
TWIN_PER = ("trial", "placement")

#: The fields of a calibration an inverse-triangulation plan does not read: the §4.4 offsets
#: and the mastering (they move the measured points afterwards), the uncertainties, the optics.
_NOT_PLANNED = ("view_offsets_mm", "view_radial_offsets_mm", "view_scales", "master",
                "uncertainty", "optics")


def _same(a, b) -> bool:
    """Exact equality of calibration values (arrays bit for bit, containers and dataclasses
    field by field)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and np.array_equal(a, b)
    if dataclasses.is_dataclass(a) and type(a) is type(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return type(a) is type(b) and a == b


def _plan(cal, grid, memo: dict | None):
    """:func:`~lts360.recon.triangulation.inverse.plan_inverse` for ``cal`` and ``grid``, as
    ``inverse_triangulate`` makes it by default; with ``memo``, made once for the
    calibrations of one trial whose geometry is the same, value for value (a drawn calibration
    and its compensated forms: only their offsets and mastering differ), and handed to each."""
    from lts360.recon.triangulation.inverse import plan_inverse

    base = memo.get(("plan", id(grid))) if memo is not None else None
    if base is None or base.grid is not grid or not all(
            _same(getattr(base.cal, f.name), getattr(cal, f.name))
            for f in dataclasses.fields(cal) if f.name not in _NOT_PLANNED):
        base = plan_inverse(cal, grid, precompute=False)
        if memo is not None:
            memo[("plan", id(grid))] = base
    return base if base.cal is cal else dataclasses.replace(base, cal=cal)


def _twin(cal, memo: dict | None = None):
    """The twin of a measurement with ``cal`` (its optics: the rig ``cal`` records, refused in
    one line without a record), as the plug-gauge study makes it: no input sensitivity.  With
    ``memo`` one twin for the calibrations of a trial (its master's shots and its image: the
    same drawn geometry), so that its scene is loaded once and moved to each surface; each
    correction is its own section of the twin's log, rendered with its own seed."""
    from lts360.twin import TwinCorrector
    from lts360.twin.rig import twin_design

    twin = memo.get("twin") if memo is not None else None
    if twin is None:
        kw = {"seed": memo["twin_seed"]} if memo is not None and "twin_seed" in memo else {}
        twin = TwinCorrector(cal, twin_design(cal), input_u=None, **kw)
        if memo is not None:
            memo["twin"] = twin
    return twin


def _raw(image, cal, grid, memo: dict | None):
    """``image`` measured with ``cal`` without compensation; with ``memo`` sampled once for the
    calibrations of a draw (the same plan: their compensations differ, applied afterwards)."""
    from lts360.recon.triangulation.inverse import inverse_triangulate

    key = ("raw", id(image), id(grid))
    if memo is not None and key in memo and memo[key][0] is image:
        return memo[key][1]
    raw = inverse_triangulate(image, cal, grid, compensate=False, plan=_plan(cal, grid, memo))
    if memo is not None:
        memo[key] = (image, raw)  # the image held: its id is not reused while the memo lives
    return raw


def measure(image, cal, grid, bias_model: str, memo: dict | None = None,
            frozen: tuple | None = None):
    """The section in ``image`` measured with ``cal`` (compensated if it holds offsets), and
    with ``bias_model="twin"`` corrected by its twin — rendered for this measurement, or with
    ``frozen`` (the keys of :func:`frozen_image_bias` but ``master``) the placement's frozen
    correction; also the uncorrected measurement and the mean bias the twin removed over the
    corrected points (µm; NaN without the twin)."""
    from lts360.recon.triangulation.inverse import recompensated

    comp = bool(cal.view_offsets_mm)
    raw = _raw(image, cal, grid, memo)
    plain = recompensated(raw, cal, comp) if comp else raw
    if bias_model == "none":
        return plain, plain, np.nan
    if frozen is not None:
        fixed, b = apply_bias(plain, frozen_image_bias(*frozen, master=bool(cal.master)))
        return fixed, plain, b
    from lts360.twin import twin_corrected

    twin = _twin(cal, memo)
    fixed = twin_corrected(plain, cal, grid, twin, compensate=comp, plan=_plan(cal, grid, memo))
    views = twin.log.sections[-1]["views"].values()
    b = np.concatenate([v["bias_mm"] for v in views]) if views else np.zeros(0)
    return fixed, plain, float(1e3 * b.mean()) if b.size else np.nan


# -- the nominal and the drawn calibrations' compensation ------------------------------
@functools.lru_cache(maxsize=16)
def _placement(frame_dir: str):
    """Stored radiance + the frame's rig (read once per process)."""
    from lts360.simulator.io import read_exr

    ch = read_exr(Path(frame_dir) / "radiance.exr")
    meta = read_frame_meta(frame_dir)
    return ch["Y"], ch["laser"], meta


@functools.lru_cache(maxsize=16)
def stored_render(frame_dir: str):
    """A placement's stored radiance as :func:`~lts360.simulator.frame.sensor_image` takes it,
    with the pixels that hold any light (``held_index``: ~0.7 % of the frame), found once per
    process instead of by a scan of the frame in every image of every trial (the same image
    bit for bit)."""
    from types import SimpleNamespace

    Y, L, _ = _placement(frame_dir)
    held = np.flatnonzero((np.asarray(Y).reshape(-1) != 0) | (np.asarray(L).reshape(-1) != 0))
    return SimpleNamespace(radiance_W_m2_sr=Y, laser_W_m2_sr=L, held_index=held)


# -- the pixels a trial reads ---------------------------------------------------------------
#: Margin (px) of the read set about the nominal plan's taps, and the distance (px) a trial's
#: plan may move its sample points from the nominal plan's while its taps stay inside it.
READ_MARGIN_PX = 3
_CHECK_MARGIN_PX = READ_MARGIN_PX - 2


@functools.lru_cache(maxsize=8)
def read_set(cal_path: str, theta_step_deg: float, placement_mm: float = DEFAULT_PLACEMENT_MM):
    """The pixels a trial's images are read at (sorted flat indices): the taps of the nominal
    calibration's plan for the trial grid (:func:`~lts360.recon.triangulation.inverse.
    plan_pixels`), widened by :data:`READ_MARGIN_PX`, ~1 % of a frame; and the mask of where a
    drawn plan's sample points may fall for its taps to be inside it (the nominal points
    widened by :data:`_CHECK_MARGIN_PX`).  Once per process: every placement is measured on
    the same grid."""
    from lts360.recon.triangulation.inverse import plan_inverse, plan_pixels

    cal = _uncompensated(cal_path)
    plan = plan_inverse(cal, _grid(theta_step_deg, placement_mm), precompute=False)
    w, h = cal.image_size
    xy = plan_pixels(plan, margin_px=READ_MARGIN_PX)
    check = np.zeros((h, w), bool)
    inner = plan_pixels(plan, margin_px=_CHECK_MARGIN_PX)
    check[inner[:, 1], inner[:, 0]] = True
    return np.sort(xy[:, 1].astype(np.int64) * w + xy[:, 0]), check


def reads_within(plan, check: np.ndarray) -> bool:
    """Whether every sample point of ``plan`` lies where ``check`` (of :func:`read_set`) allows:
    its cubic taps are then inside the read set (the point's pixel ``floor(uv)`` within
    :data:`_CHECK_MARGIN_PX` of a nominal point's, its taps ``−1 … +2`` from it)."""
    h, w = check.shape
    flat = check.reshape(-1)
    for vp in plan.views.values():
        u, v = vp.uv[..., 0], vp.uv[..., 1]
        with np.errstate(invalid="ignore"):
            ok = (u >= 0) & (v >= 0) & (u < w) & (v < h)       # NaN: not sampled
        if not np.all(ok | np.isnan(u) | np.isnan(v)):
            return False
        # the pixel floor(uv) (truncation: non-negative here)
        if not flat[v[ok].astype(np.int64) * w + u[ok].astype(np.int64)].all():
            return False
    return True


def _read(memo: dict | None, plan):
    """The read set for images measured with ``plan`` (``memo["read_set"]``, from
    :func:`read_set`), or None — the full frame — without one or where the plan reads
    outside it (a calibration drawn far from the nominal one)."""
    rs = memo.get("read_set") if memo is not None else None
    if rs is None:
        return None
    key = ("reads_within", id(plan.views))  # the plan's forms for a draw's calibrations
    if key not in memo or memo[key][0] is not plan.views:
        memo[key] = (plan.views, reads_within(plan, rs[1]))
    return rs[0] if memo[key][1] else None


@functools.lru_cache(maxsize=2)
def _calibration(path: str):
    from lts360.recon.model import load_calibration

    return load_calibration(path)


def _compensate(cal, renders: str, rig_name: str, theta_step_deg: float,
                noise_seed: int | None = None, shots: int = 1,
                placement_mm: float = DEFAULT_PLACEMENT_MM, master: bool = False,
                bias_model: str = "none", memo: dict | None = None, frozen: str | None = None):
    """``cal`` with the §4.4 view offsets measured with it on the reference placement
    (``placement_00``), whatever offsets ``cal`` held.  The reference image is noise-free, or
    with ``noise_seed`` has realistic sensor noise and a speckle pattern drawn from it; then
    ``shots`` such images (the gauge turned between them: a new speckle pattern each) are
    fitted jointly.  ``master``: the fit knows the gauge's diameter
    (:func:`~lts360.recon.calibration.compensation.master_fit`: per view a radial offset
    too); with ``bias_model="twin"`` its shots are corrected by their twin first
    (:func:`~lts360.twin.twin_corrected_raw`, as the plug-gauge study and ``lts360
    compensate`` do: the master then sets what the twin leaves).

    ``memo``: a dict shared by the calls of one trial, all with the same ``cal``: the reference
    shots are imaged and measured once for the configurations a trial compares (the same
    images, the same measurements), not once per configuration.  ``frozen`` (the calibration
    file's path): the shots' twin correction is the reference placement's frozen one
    (:func:`~lts360.experiments.mc_measure.frozen_reference_bias`)."""
    from lts360.recon.calibration.compensation import joint_view_offsets

    key = ("shots", renders, rig_name, float(theta_step_deg), noise_seed, int(shots),
           float(placement_mm))
    if memo is not None and key in memo:
        cal, results = memo[key]
    else:
        cal, results = _reference_shots(cal, renders, rig_name, theta_step_deg, noise_seed,
                                        shots, placement_mm, memo)
        if memo is not None:
            memo[key] = (cal, results)
    if master:
        from lts360.recon.calibration.compensation import master_fit

        if bias_model == "twin":
            from lts360.twin import twin_corrected_raw

            grid = _grid(theta_step_deg, placement_mm)
            if frozen is not None:  # the calibration file's path: the frozen correction's
                bias = frozen_reference_bias(frozen, renders, rig_name, float(theta_step_deg),
                                             float(placement_mm))
                results = [apply_bias(r, bias, raw=True)[0] for r in results]
            else:
                twin, plan = _twin(cal, memo), _plan(cal, grid, memo)
                results = [twin_corrected_raw(r, cal, grid, twin, plan=plan) for r in results]
        fit = master_fit(results, GAUGE_DIAMETER_MM)
        return dataclasses.replace(cal, view_offsets_mm=fit.offsets_mm,
                                   view_radial_offsets_mm=fit.radial_offset_mm,
                                   view_scales=fit.scale, master=fit.to_dict())
    offsets = joint_view_offsets(results)
    return dataclasses.replace(cal, view_offsets_mm=offsets)


def _reference_shots(cal, renders: str, rig_name: str, theta_step_deg: float,
                     noise_seed: int | None, shots: int, placement_mm: float,
                     memo: dict | None = None):
    """``cal`` without any compensation, and the reference placement's shots measured with
    it (:func:`_compensate`'s images: noise-free, or ``shots`` noisy ones from ``noise_seed``;
    a noisy one drawn on :func:`read_set`'s pixels where the plan reads within them)."""
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    res0 = stored_render(str(Path(renders) / "placement_00"))
    noisy = noise_seed is not None
    rig = load_rig(rig_name)
    cal = dataclasses.replace(cal, view_offsets_mm={}, view_radial_offsets_mm={},
                              view_scales={}, master={})
    grid = _grid(theta_step_deg, placement_mm)
    plan = _plan(cal, grid, memo)
    read = _read(memo, plan) if noisy else None
    results = []
    for j in range(int(shots) if noisy else 1):  # noise-free shots would all be the same
        s = int(noise_seed) + 2 * j if noisy else 0
        ref, _, _ = sensor_image(rig, res0, noise="realistic" if noisy else "none", seed=s,
                                 speckle=noisy, speckle_seed=s + 1 if noisy else None,
                                 read=read)
        results.append(inverse_triangulate(ref, cal, grid, plan=plan))
    return cal, results


@functools.lru_cache(maxsize=8)
def _nominal_calibration(path: str, renders: str, rig_name: str, theta_step_deg: float,
                         placement_mm: float = DEFAULT_PLACEMENT_MM, master: bool = False,
                         bias_model: str = "none"):
    """The file's calibration compensated at the reference placement (once per process)."""
    return _compensate(_calibration(path), renders, rig_name, theta_step_deg,
                       placement_mm=placement_mm, master=master,
                       bias_model=bias_model if master else "none")


def _uncompensated(path: str):
    """The file's calibration without any compensation (§4.4 offsets, mastering)."""
    return dataclasses.replace(_calibration(path), view_offsets_mm={}, view_radial_offsets_mm={},
                               view_scales={}, master={})


@functools.lru_cache(maxsize=8)
def _grid(theta_step_deg: float, placement_mm: float = DEFAULT_PLACEMENT_MM):
    """The fixed band about the gauge's radius: ±0.5 mm at the nominal placements, widened by
    the placement radius beyond them."""
    from lts360.recon.triangulation.grid import CylGrid

    r0 = GAUGE_DIAMETER_MM / 2.0
    half = 0.5 + max(0.0, float(placement_mm) - DEFAULT_PLACEMENT_MM)
    return CylGrid.from_ranges((r0 - half, r0 + half), theta_step_deg=theta_step_deg,
                               r_step_mm=0.005)


# -- the frozen correction -----------------------------------------------------------------
def _bias_of(result, entry) -> dict[str, np.ndarray]:
    """Per view, the bias (mm) a twin's log ``entry`` removed from ``result`` on each ray of
    the grid (NaN where it corrected nothing)."""
    out = {}
    for name, v in result.views.items():
        b = np.full(np.shape(v.r_mm), np.nan)
        rec = entry["views"].get(name)
        if rec is not None and len(rec["theta_rad"]):
            at = np.isin(np.asarray(v.theta_rad), rec["theta_rad"])
            b[at] = rec["bias_mm"]
        out[name] = b
    return out


def _noise_free_image(frame_dir: str, rig_name: str):
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    return sensor_image(load_rig(rig_name), stored_render(frame_dir), noise="none")[0]


def _frozen(image, cal, grid, compensate: bool) -> dict[str, np.ndarray]:
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.twin import twin_corrected

    plain = inverse_triangulate(image, cal, grid, compensate=compensate)
    twin = _twin(cal)
    twin_corrected(plain, cal, grid, twin, compensate=compensate)
    return _bias_of(plain, twin.log.sections[-1])


@functools.lru_cache(maxsize=32)
def frozen_image_bias(frame_dir: str, cal_path: str, renders: str, rig_name: str,
                      theta_step_deg: float, placement_mm: float, *,
                      master: bool) -> dict[str, np.ndarray]:
    """The twin's correction of a placement's section (per view, mm on each ray of the grid;
    NaN where none): its noise-free image measured with the nominal calibration compensated
    (and with ``master`` mastered) at the reference placement, as the trials measure theirs;
    once per process."""
    cal = _nominal_calibration(cal_path, renders, rig_name, theta_step_deg, placement_mm,
                               master, "twin" if master else "none")
    return _frozen(_noise_free_image(frame_dir, rig_name), cal,
                   _grid(theta_step_deg, placement_mm), True)


@functools.lru_cache(maxsize=8)
def frozen_reference_bias(cal_path: str, renders: str, rig_name: str, theta_step_deg: float,
                          placement_mm: float) -> dict[str, np.ndarray]:
    """The twin's correction of the reference placement's shot measured without compensation
    (the master's shots, :func:`~lts360.twin.twin_corrected_raw`), frozen as
    :func:`frozen_image_bias`."""
    return _frozen(_noise_free_image(str(Path(renders) / "placement_00"), rig_name),
                   _uncompensated(cal_path), _grid(theta_step_deg, placement_mm), False)


def apply_bias(result, bias: dict, *, raw: bool = False):
    """``result`` with ``bias`` (per view, mm on each ray) subtracted from its valid points
    where the bias is known, and the mean bias removed (µm; NaN if none); ``raw``: the
    corrected radii also as ``r_raw_mm``, as :func:`~lts360.twin.twin_corrected_raw` returns
    a master's shot."""
    views, removed = {}, []
    for name, v in result.views.items():
        b = bias.get(name)
        if b is None:
            views[name] = v
            continue
        ok = v.valid & np.isfinite(b)
        r = np.where(ok, v.r_mm - np.where(ok, b, 0.0), v.r_mm)
        removed.append(b[ok])
        kw = {"r_raw_mm": np.where(np.isfinite(r), r, v.r_raw_mm)} if raw else {}
        views[name] = dataclasses.replace(v, r_mm=r, **kw)
    b = np.concatenate(removed) if removed else np.zeros(0)
    return (dataclasses.replace(result, views=views),
            float(1e3 * b.mean()) if b.size else float("nan"))
