"""``lts360 study examples``: the measurement examples of paper §4.6 (Figs 11–18).

Each of the eight objects is scanned with the paper's number of sections and pitch (realistic
noise by default), measured by inverse triangulation and scored against its ground truth
(analytic r(θ, z) and the mesh).  Per object: ``clouds/<object>.ply`` (points with their view
and quality), ``figures/<object>.png`` (the points coloured by view — red direct, blue and
green mirrors, as in the paper — and one section against the truth), ``inspection/<object>/``
(the ``lts360 inspect`` report against the object's analytic nominal, true values beside the
measured ones) and a row of the error table.  One trial per object, so an interrupted study
resumes object by object.

Each scan is measured as ``lts360 measure`` measures it with no ``--radius-mm``: the radial band
found from the image, the scan's own rejection pass.  The calibration is the rendered frames'
true one by default (``--calibration`` to measure
with an estimated one): the examples then show the algorithm and the optics, not the
calibration.  Occlusions (the valleys between a cable's strands, the cut tube's gap) are
reported as missing coverage, not as error.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lts360.experiments.runner import Trial, TrialOutput, plan_trials, run_study, trial_setup

__all__ = ["PAPER_EXAMPLES", "EXTRA_EXAMPLES", "examples_trial", "examples_params", "render_scan", "stored_scan", "measure_scan",
           "run_examples_study", "format_examples"]

#: Paper §4.6: object → (figure, sections, pitch mm).
PAPER_EXAMPLES = {
    "pvc-pipe": (11, 26, 0.68), "alu-pipe": (12, 26, 0.68), "grooved-shaft": (13, 20, 0.68),
    "cable-6": (14, 40, 0.34), "cable-8": (15, 39, 0.34), "cube": (16, 25, 0.68),
    "undercut-shaft": (17, 25, 0.68), "cut-tube": (18, 25, 0.68),
}
#: Objects beyond the paper's, scanned as the paper scans its shafts (figure 0: none).
EXTRA_EXAMPLES = {"polished-shaft": (0, 25, 0.68)}
VIEW_COLOURS = {0: "tab:red", 1: "tab:blue", 2: "tab:green"}


def examples_trial(trial: Trial) -> TrialOutput:
    """Render and measure one object's scan; write its cloud and figure; return its metrics."""
    p = trial.params
    frames = p.get("frames", "")
    scan = stored_scan(p, trial.seed, frames) if frames else render_scan(p, trial.seed)
    return measure_scan(p, scan)


def _same_trial(p: dict) -> dict:
    """The parameters that make a scan's frames (not where the study writes)."""
    return {k: v for k, v in p.items() if k not in ("out", "frames", "calibration")}


def stored_scan(p: dict, seed: int, frames_dir) -> dict:
    """:func:`render_scan`'s frames, read from ``frames_dir/<object>.npz`` when that file holds
    the scan of the same parameters and seed, else rendered and stored there (so that a
    study measured again after a change of the measurement renders nothing)."""
    path = Path(frames_dir) / f"{p['object']}.npz"
    key = json.dumps(_same_trial(p), sort_keys=True)
    if path.exists():
        with np.load(path) as f:
            if str(f["params"]) == key and int(f["seed"]) == int(seed):
                return {"images": f["images"], "z_mm": f["z_mm"],
                        "truth": json.loads(str(f["truth"])), "render_s": float(f["render_s"])}
    scan = render_scan(p, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp.npz")
    np.savez_compressed(tmp, images=scan["images"], z_mm=scan["z_mm"],
                        truth=json.dumps(scan["truth"]), render_s=scan["render_s"],
                        params=key, seed=int(seed))
    tmp.replace(path)
    return scan


def render_scan(p: dict, seed: int) -> dict:
    """The frames of one trial's scan (trial parameters ``p``, the trial's ``seed``): a dict
    with ``images`` (n, H, W), ``z_mm`` (n,), ``truth`` (the first frame's rig truth, JSON
    types) and ``render_s`` (wall time of all frames)."""
    import time

    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.reuse import SceneCache

    rig, obj = trial_setup(p)
    n, pitch = int(p["sections"]), float(p["pitch_mm"])
    zc = float(np.mean(obj.measured_zone_z_mm))
    zs = zc + (np.arange(n) - (n - 1) / 2.0) * pitch
    images, t_render, rig_truth = [], 0.0, None
    scenes = SceneCache()  # built once for the object's scan: each section moves it
    for k, z in enumerate(zs):
        t0 = time.perf_counter()
        frame = simulate_frame(rig, obj, z_mm=float(z), spp=int(p["spp"]),
                               seed=seed + k, noise=p["noise"], scenes=scenes,
                               max_scatter=int(p.get("max_scatter", 0)))
        t_render += time.perf_counter() - t0
        if rig_truth is None:
            rig_truth = json.loads(json.dumps(frame.truth, default=lambda v: v.tolist()))
        images.append(frame.image)
    return {"images": np.stack(images), "z_mm": zs, "truth": rig_truth, "render_s": t_render}


def measure_scan(p: dict, scan: dict) -> TrialOutput:
    """Measure the frames of :func:`render_scan` as ``lts360 measure`` does (the band found
    from the image, the rejections on unless ``p["reject"]`` is false), write the object's
    cloud, figure and inspection under ``p["out"]`` and return the trial's metrics."""
    import time

    from lts360.experiments.score import score_cloud
    from lts360.recon.model import calibration_from_frame_truth, load_calibration
    from lts360.recon.triangulation.cloud import write_cloud
    from lts360.recon.triangulation.measure import Section, measure_sections_following

    _, obj = trial_setup(p)
    zs, rig_truth = np.asarray(scan["z_mm"], dtype=float), scan["truth"]
    n, t_render = len(zs), float(scan["render_s"])
    cal = load_calibration(p["calibration"]) if p["calibration"] else \
        calibration_from_frame_truth(rig_truth)
    sections = [Section(Path(f"{obj.name}-{k:03d}"), float(z), image=img)
                for k, (z, img) in enumerate(zip(zs, scan["images"]))]
    # the radial band found from the image, as `lts360 measure` does with no --radius-mm
    t0 = time.perf_counter()
    cloud, _, band_log = measure_sections_following(
        sections, cal, theta_step_deg=float(p["theta_step_deg"]),
        r_step_mm=float(p["r_step_mm"]), reject=p.get("reject", True),
        multipeak=p.get("multipeak", True))
    t_measure = time.perf_counter() - t0
    out = Path(p["out"])
    (out / "clouds").mkdir(parents=True, exist_ok=True)
    write_cloud(out / "clouds" / f"{obj.name}.ply", cloud)
    m = score_cloud(cloud, obj, rig_truth=rig_truth)
    _figure(obj, cloud, zs, out / "figures" / f"{obj.name}.png", m)
    _inspection(obj, cloud, zs, cal, out / "inspection" / obj.name)
    views = ("direct", "left", "right")
    vals = {"n_points": m["n_points"], "coverage_deg": m["coverage_deg"],
            "rms_mm": m["rms_mm"], "mean_mm": m["mean_mm"], "p95_mm": m["p95_mm"],
            "max_abs_mm": m["max_abs_mm"],
            "mesh_rms_mm": m["mesh_distance"]["rms_mm"], "mesh_mean_mm": m["mesh_distance"]["mean_mm"],
            "n_spurious": m.get("n_spurious", 0),
            "n_rejected_fading": m["rejected"]["fading"],
            "n_rejected_notch": m["rejected"]["notch"],
            "n_rejected_hidden": m["rejected"]["hidden"],
            "n_rejected_flank": m["rejected"]["flank"],
            "n_rejected_neighbours": m["rejected"]["neighbours"],
            "spurious_rms_mm": (m.get("spurious") or {}).get("rms_mm") or 0.0,
            "n_band_searches": len(band_log.searched),
            "render_s_per_section": t_render / n, "measure_s_per_section": t_measure / n,
            "view_rms_mm": np.array([m["views"].get(v, {}).get("rms_mm") or np.nan for v in views]),
            "view_coverage_deg": np.array([m["views"].get(v, {}).get("coverage_deg", 0.0)
                                           for v in views])}
    vals = {k: (np.nan if v is None else v) for k, v in vals.items()}
    return TrialOutput(values=vals, dims={"view_rms_mm": ("view",), "view_coverage_deg": ("view",)},
                       coords={"view": np.array(views)})


def _inspection(obj, cloud, zs, cal, out: Path) -> None:
    """The object's inspection report (``lts360 inspect``) against its analytic nominal, with
    the true values beside the measured ones; an object the inspection cannot read (no
    analytic contour, too few points) gets a one-line ``inspection.txt`` saying why."""
    from lts360.inspect.nominal import nominal_from_spec
    from lts360.inspect.report import write_report
    from lts360.inspect.run import inspect_cloud

    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        try:
            nominal = nominal_from_spec(obj.spec)
            nominal.contour(float(zs[0]))
        except ValueError:
            nominal = None
        ins = inspect_cloud(cloud, nominal=nominal, calibration=cal, truth=(obj, list(zs)),
                            source=f"clouds/{obj.name}.ply")
        write_report(ins, out)
    except ValueError as exc:
        (out.parent / f"{obj.name}.txt").write_text(f"{obj.name}: no inspection: {exc}\n")


def _figure(obj, cloud, zs, path: Path, metrics: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    c = cloud.select(cloud.valid)
    fig = plt.figure(figsize=(12, 5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    step = max(1, len(c) // 40000)
    for code, colour in VIEW_COLOURS.items():
        m = c.view[::step] == code
        ax.scatter(*c.points_mm[::step][m].T, s=0.3, c=colour)
    ax.set_title(f"{obj.name}: {len(zs)} sections, {metrics['n_points']} points")
    ax.set_box_aspect((1, 1, 1))
    ax2 = fig.add_subplot(1, 2, 2)
    k = len(zs) // 2
    sel = c.section == k
    th = np.linspace(-np.pi, np.pi, 1441)
    local_z = float(np.median(obj.to_object_frame(c.points_mm[sel])[:, 2])) if sel.any() else 0.0
    r = obj.radius_fn(th, np.full_like(th, local_z))
    T = obj.T_world_object
    truth = np.column_stack([r * np.cos(th), r * np.sin(th), np.full_like(th, local_z)]) @ T[:3, :3].T + T[:3, 3]
    ax2.plot(truth[:, 0], truth[:, 1], "k-", lw=0.6, label="truth")
    for code, colour in VIEW_COLOURS.items():
        m = sel & (c.view == code)
        ax2.plot(c.points_mm[m, 0], c.points_mm[m, 1], ".", ms=1.5, c=colour)
    ax2.set_aspect("equal")
    ax2.set_title(f"section {k} (z = {zs[k]:.2f} mm): rms {metrics['rms_mm'] * 1e3:.1f} µm, "
                  f"coverage {metrics['coverage_deg']:.0f}°")
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(path)


def examples_params(out: Path, *, objects=None, noise: str = "realistic", spp: int = 16,
                    calibration=None, theta_step_deg: float = 0.2, r_step_mm: float = 0.01,
                    section_scale: float = 1.0, rig: str = "paper",
                    max_scatter: int | str = "auto") -> list[dict]:
    """The trials' parameters of :func:`run_examples_study` (one per object, in order);
    ``max_scatter`` ``"auto"``: per object, by its material
    (:func:`lts360.scenes.materials.auto_max_scatter`)."""
    from lts360.scenes.materials import resolve_max_scatter
    from lts360.scenes.objects import build_object

    names = list(objects or PAPER_EXAMPLES)
    params, bounces = [], []
    for name in names:
        known = PAPER_EXAMPLES | EXTRA_EXAMPLES
        if name not in known:
            raise ValueError(f"examples: unknown object {name!r}; choose from "
                             f"{', '.join(known)}")
        fig, n, pitch = known[name]
        params.append({"object": name, "figure": fig, "sections": max(1, round(n * section_scale)),
                       "pitch_mm": pitch, "noise": noise, "spp": spp, "rig": rig,
                       "calibration": "" if calibration is None else str(Path(calibration).resolve()),
                       "theta_step_deg": theta_step_deg, "r_step_mm": r_step_mm,
                       "out": str(Path(out).resolve())})
        bounces.append(resolve_max_scatter(max_scatter, build_object(name).material
                                           if max_scatter == "auto" else None))
    if any(bounces):  # only then: the trials of earlier studies keep their parameters
        for p, ms in zip(params, bounces):  # every trial names it (the runner's one schema)
            p["max_scatter"] = ms
    return params


def run_examples_study(out_dir, *, objects=None, seed: int = 0, noise: str = "realistic",
                       spp: int = 16, calibration=None, theta_step_deg: float = 0.2,
                       r_step_mm: float = 0.01, section_scale: float = 1.0, rig: str = "paper",
                       workers: int | None = 1, dask_address: str | None = None,
                       max_scatter: int | str = "auto", frames_dir=None) -> dict:
    """Run the examples; ``section_scale`` < 1 scans fewer sections (quick looks);
    ``max_scatter`` > 0 renders the laser light's interreflections, ``"auto"`` (default) one
    bounce for the shiny objects (alu pipe, cut tube, polished shaft) and none for the others
    (the objects of :data:`EXTRA_EXAMPLES` may be named too); ``frames_dir``: keep each scan's frames there
    and measure the stored ones when a later study asks for the same scan
    (:func:`stored_scan`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    params = examples_params(out, objects=objects, noise=noise, spp=spp, calibration=calibration,
                             theta_step_deg=theta_step_deg, r_step_mm=r_step_mm,
                             section_scale=section_scale, rig=rig, max_scatter=max_scatter)
    if frames_dir is not None:
        for q in params:
            q["frames"] = str(Path(frames_dir).resolve())
    ds = run_study(out / "trials", plan_trials(params, seed), examples_trial, name="examples",
                   workers=workers, dask_address=dask_address)
    table = {}
    for i, name in enumerate(ds["object"].values):
        keys = ("n_points", "coverage_deg", "rms_mm", "mean_mm", "p95_mm", "max_abs_mm",
                "mesh_rms_mm", "mesh_mean_mm", "n_spurious", "n_rejected_fading",
                "n_rejected_notch", "n_rejected_hidden", "n_rejected_flank",
                "n_rejected_neighbours", "spurious_rms_mm", "render_s_per_section",
                "measure_s_per_section")
        row = {k: float(ds[k].values[i]) if k in ds else float("nan") for k in keys}
        row.update(figure=int(ds["figure"].values[i]), sections=int(ds["sections"].values[i]),
                   pitch_mm=float(ds["pitch_mm"].values[i]))
        table[str(name)] = row
    (out / "table.json").write_text(json.dumps(table, indent=2))
    (out / "table.txt").write_text(format_examples(table) + "\n")
    return table


def _rejected(row: dict) -> str:
    f, n = row.get("n_rejected_fading"), row.get("n_rejected_notch")
    if f is None or n is None or not (np.isfinite(f) and np.isfinite(n)):
        return "—"  # a table from before the rejection
    out = f"{int(f)}/{int(n)}"
    # the later criteria: older tables lack them
    for key in ("n_rejected_hidden", "n_rejected_flank", "n_rejected_neighbours"):
        c = row.get(key)
        if c is None or not np.isfinite(c):
            break
        out += f"/{int(c)}"
    return out


def format_examples(table: dict) -> str:
    lines = [f"{'object':16s} {'fig':>3s} {'sections':>8s} {'pitch':>6s} {'points':>8s} "
             f"{'coverage':>8s} {'rms µm':>7s} {'mean µm':>8s} {'p95 µm':>7s} {'max µm':>7s} "
             f"{'normal rms':>10s} {'rejected f/n/h/s/b':>24s} {'spurious':>8s}"]
    for name, r in table.items():
        lines.append(f"{name:16s} {r['figure']:3d} {r['sections']:8d} {r['pitch_mm']:6.2f} "
                     f"{int(r['n_points']):8d} {r['coverage_deg']:7.1f}° {r['rms_mm'] * 1e3:7.1f} "
                     f"{r['mean_mm'] * 1e3:+8.1f} {r['p95_mm'] * 1e3:7.1f} {r['max_abs_mm'] * 1e3:7.1f} "
                     f"{r['mesh_rms_mm'] * 1e3:10.1f} "
                     f"{_rejected(r):>24s} {int(r['n_spurious']):8d}")
    lines.append("(coverage: mean angle per section with measurable points, 0.5° bins; errors: "
                 "analytic radial error r − r(θ, z), signed, positive outside; normal rms: "
                 "distance to the mesh; rejected f/n/h/s/b: rows rejected without the truth as "
                 "FADING / NOTCH / HIDDEN / FLANK (the sheet on a slope along the axis) / "
                 "NEIGHBOURS (both neighbouring sections rejected it along the helix); spurious: points still valid where the true surface is hidden from "
                 "the view or unlit — left out of the errors and the coverage)")
    return "\n".join(lines)
