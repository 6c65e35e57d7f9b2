"""``lts360 demo``: the main job, doing honestly what exists today.

Builds the paper rig, prints its coverage table, writes every object's ground-truth mesh
(world frame, PLY), a figure of the rig with the covered section and the image plane, a
figure of the objects' true sections, and renders the plug gauge in the rig (noise-free and
with realistic sensor noise and speckle) as frame directories with their exact truth,
measured with the true calibration.  Then the paper end to end: the rig calibrated from
rendered chessboard images (camera, both mirrors, laser plane) and the plug gauge placed ten
times and measured with that calibration as a user would (§4.4, mastered with the gauge's
known diameter, each placement corrected by its twin) — the paper's §4.5 table beside ours
and beside the paper's method (§4.4 alone) on the same images.  Output goes to
a temporary directory that is renamed to ``out`` at the end, so an interrupted demo never
leaves a half-written result.
"""

from __future__ import annotations

import json
import shutil
import threading
import time
from pathlib import Path

import numpy as np

from lts360.experiments.figures import plot_rig, plot_sections
from lts360.experiments.report import format_coverage, format_rig
from lts360.folders import frame_file, read_frame_meta
from lts360.scenes.coverage import coverage
from lts360.scenes.objects import build_object, object_types
from lts360.scenes.rig_io import load_rig, rig_to_toml

__all__ = ["run_demo"]


def _measure_frames(root: Path, obj, echo, lock) -> dict:
    """Inverse triangulation of the demo frames with the true calibration (under ``lock``: its
    Dr.Jit kernel), then scoring."""
    from lts360.experiments.score import score_cloud
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.cloud import write_cloud
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.measure import collect_sections, measure_sections
    from lts360.simulator.io import write_json

    out = {}
    r = obj.params["diameter_mm"] / 2.0
    grid = CylGrid.from_ranges((r - 2.0, r + 2.0), theta_step_deg=0.1, r_step_mm=0.005)
    echo(f"\nplug gauge measured with the true calibration (inverse triangulation, centroid, "
         f"{grid.n_theta} θ × {grid.n_r} r):")
    echo(f"  {'frame':24s} {'points':>7s} {'coverage':>9s} {'radius bias':>12s} {'rms':>9s} "
         f"{'direct':>8s} {'left':>8s} {'right':>8s}")
    for name in ("plug-gauge-none", "plug-gauge-realistic"):
        d = root / "frames" / name
        cal = load_calibration(frame_file(d))
        t0 = time.perf_counter()
        with lock:
            cloud = measure_sections(collect_sections([d]), cal, grid)
        dt = time.perf_counter() - t0
        write_cloud(d / "cloud.ply", cloud)
        m = score_cloud(cloud, obj, rig_truth=read_frame_meta(d))
        m["measure_seconds"] = dt
        write_json(d / "metrics.json", m)
        _inspect_gauge(d, cloud, obj, cal)
        views = [m["views"].get(v, {}).get("rms_mm") for v in ("direct", "left", "right")]
        cells = " ".join(f"{v * 1e3:6.1f}µm" if v is not None else f"{'—':>8s}" for v in views)
        echo(f"  {name:24s} {m['n_points']:7d} {m['coverage_deg']:8.1f}° "
             f"{m.get('radius_bias_mm', float('nan')) * 1e3:10.2f}µm {m['rms_mm'] * 1e3:7.1f}µm {cells}")
        out[name] = {k: m.get(k) for k in ("n_points", "coverage_deg", "radius_bias_mm", "rms_mm",
                                          "fitted_diameter_mm", "measure_seconds")}
    echo("  (rms per point; the radius bias is that of a circle fitted to all points)")
    return out


def _inspect_gauge(d: Path, cloud, obj, cal) -> None:
    """``inspection/``: the ``lts360 inspect`` report of a demo frame against the gauge's
    nominal, with the true values."""
    from lts360.inspect.nominal import nominal_from_spec
    from lts360.inspect.report import write_report
    from lts360.inspect.run import inspect_cloud

    ins = inspect_cloud(cloud, nominal=nominal_from_spec(obj.spec), calibration=cal,
                        truth=(obj, [0.0]), source=f"frames/{d.name}/cloud.ply")
    write_report(ins, d / "inspection")


def run_demo(out: Path, *, radius_mm: float = 10.0, rig_name: str = "paper", render: bool = True,
             spp: int = 16, seed: int = 0, paper: bool = True, gauge_trials: int = 10,
             gauge_options: dict | None = None, echo=print) -> dict:
    """Run the demo into ``out`` (replaced atomically) and return a summary dictionary.

    ``render`` needs an active Mitsuba variant (the CLI sets it).  ``gauge_options``: the
    plug-gauge study's steps (``compensate``, ``master``, ``bias_model``, ``steps`` of
    :func:`~lts360.experiments.gauge_study.run_plug_gauge_study`; default: all on).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {str(out)!r} exists and is not a directory")
    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / "objects").mkdir(parents=True)
    t0 = time.perf_counter()
    with _Background(tmp / "calibration", rig_name=rig_name, seed=seed,
                     start=render and paper) as calibration_shots:
        summary = _run(tmp, rig_name=rig_name, radius_mm=radius_mm, render=render, spp=spp,
                       seed=seed, echo=echo, lock=calibration_shots.lock)
        if calibration_shots.future is not None:
            summary["timing_note"] = ("the calibration images rendered on another thread from "
                                      "the start: the frames' render and measurement times "
                                      "include that contention")
        if render and paper:
            summary["paper"] = _paper(tmp, rig_name=rig_name, seed=seed, trials=gauge_trials,
                                      echo=echo, options=gauge_options or {},
                                      rendered=calibration_shots.result())
    (tmp / "summary.json").write_text(json.dumps(summary, indent=2))
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    what = "rig.png, sections.png, rig.toml, summary.json, objects/*.ply"
    if render:
        what += ", frames/"
    if render and paper:
        what += (", calibration/ (calibration.json, report.json, fig8.png, images/), "
                 "plug-gauge/ (table.txt, plug-gauge.png, clouds/*.ply, trials/results.nc)")
    echo(f"\nwrote {out}/ ({what}) in {time.perf_counter() - t0:.1f} s")
    return summary


class _Background:
    """The paper's calibration images (:func:`~lts360.experiments.calibration_run.render_calibration`,
    realistic noise) rendered on a thread of their own from the demo's start: the rig, the
    objects and the two frames that come first are mostly single-threaded Python, and the
    renderer fills the other core meanwhile.  The images are those of a sequential run (every
    shot has its own seed).  ``lock``: held by the shots' rendering and by the main thread's
    own Mitsuba and Dr.Jit work (the frames, their measurement), so that the two threads
    never trace or launch kernels at once — their Python, NumPy and OpenCV work overlaps.
    Leaving the ``with`` block early (an error, Ctrl-C) stops the rendering after the shot
    in hand."""

    def __init__(self, folder: Path, *, rig_name: str, seed: int, start: bool):
        self.folder, self.rig_name, self.seed, self.start = folder, rig_name, seed, start
        self.pool = self.future = None
        self.stop = None
        self.lock = threading.Lock()

    def __enter__(self) -> _Background:
        if self.start:
            from concurrent.futures import ThreadPoolExecutor

            from lts360.experiments.calibration_run import render_calibration

            self.stop = threading.Event()
            self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lts360-calibration")
            self.future = self.pool.submit(render_calibration, self.folder, rig_name=self.rig_name,
                                           noise="realistic", seed=self.seed,
                                           say=lambda *_: None, bar=False, stop=self.stop,
                                           lock=self.lock)
        return self

    def result(self):
        return self.future.result()

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.pool is not None:
            if exc_type is not None:
                self.stop.set()
            self.pool.shutdown(wait=True)


def _run(tmp: Path, *, rig_name: str, radius_mm: float, render: bool, spp: int, seed: int,
         echo, lock) -> dict:
    """The rig, its coverage, the objects and the plug gauge's two frames measured with the
    true calibration: everything before the paper's calibration (``lock``: held for the
    frames' rendering and measurement, see :class:`_Background`)."""
    rig = load_rig(rig_name)
    echo(format_rig(rig))
    cov = coverage(rig, radius_mm)
    echo(format_coverage(rig, cov))
    (tmp / "rig.toml").write_text(rig_to_toml(rig))
    plot_rig(rig, cov, tmp / "rig.png")

    summary = {"rig": rig.name, "coverage_deg": cov.coverage_deg,
               "windows_deg": {v: cov.windows(v) for v in cov.views()}, "objects": {}}
    sections = {}
    echo(f"\n{'object':16s} {'vertices':>9s} {'faces':>9s} watertight  build")
    theta = np.linspace(-np.pi, np.pi, 3601)
    for name, entry in object_types().items():
        if name == "cable" or entry.from_file:  # generic cable = cable-8; a part needs its file
            continue
        t = time.perf_counter()
        obj = build_object(name)
        mesh = obj.mesh_world()
        mesh.export(tmp / "objects" / f"{name}.ply")
        dt = time.perf_counter() - t
        echo(f"{name:16s} {len(mesh.vertices):9d} {len(mesh.faces):9d} {str(mesh.is_watertight):10s} "
             f"{dt:5.2f} s")
        summary["objects"][name] = {"spec": obj.spec, "vertices": len(mesh.vertices),
                                    "faces": len(mesh.faces), "watertight": bool(mesh.is_watertight),
                                    "material": obj.material.name}
        if obj.radius_fn is not None:
            sections[name] = (theta, obj.radius_fn(theta, np.zeros_like(theta)))
    plot_sections(sections, tmp / "sections.png")

    if render:
        from lts360.simulator.frame import simulate_frame, write_frame

        gauge = build_object("plug-gauge")
        for noise in ("none", "realistic"):
            with lock:
                frame = simulate_frame(rig, gauge, spp=spp, seed=seed, noise=noise)
            write_frame(tmp / "frames" / f"plug-gauge-{noise}", frame)
            echo(f"rendered the plug gauge ({noise} noise): {frame.render.seconds:.2f} s "
                 f"({frame.render.variant}, {spp} spp), exposure "
                 f"{frame.exposure_time_s * 1e6:.0f} µs -> frames/plug-gauge-{noise}/")
        summary["frames"] = ["frames/plug-gauge-none", "frames/plug-gauge-realistic"]
        summary["measurements"] = _measure_frames(tmp, gauge, echo, lock)
    return summary


def _paper(root: Path, *, rig_name: str, seed: int, trials: int, echo,
           options: dict, rendered) -> dict:
    """The paper end to end: calibrate from rendered chessboard images (realistic noise), then
    the plug-gauge evaluation of §4.5 with that calibration, measured as a user would (§4.4,
    mastered with the gauge's known diameter, the twin; ``options`` switch them), beside the
    paper's method (§4.4 alone) on the same images."""
    from lts360.experiments.calibration_run import format_report, run_calibrate
    from lts360.experiments.gauge_study import format_gauge_table, run_plug_gauge_study

    t = time.perf_counter()
    echo("\ncalibration from rendered chessboard images (paper §4.2–4.3, realistic noise):")
    report = run_calibrate(root / "calibration", rig_name=rig_name, noise="realistic", seed=seed,
                           rendered=rendered, say=lambda *_: None)
    echo(format_report(report))
    echo(f"  ({time.perf_counter() - t:.0f} s; the images rendered in the background from the "
         f"start) -> calibration/")
    t = time.perf_counter()
    echo(f"\nplug gauge placed {trials} times, measured with that calibration (paper §4.5):")
    table = run_plug_gauge_study(root / "plug-gauge", trials=trials, seed=seed,
                                 calibration=root / "calibration" / "calibration.json",
                                 noise="realistic", rig=rig_name, say=echo, **options)
    echo(format_gauge_table(table))
    echo(f"  ({time.perf_counter() - t:.0f} s) -> plug-gauge/")
    return {"calibration": report.get("accuracy"), "plug_gauge": table}
