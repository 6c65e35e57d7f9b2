"""The ``lts360`` command line: thin wrappers that parse, validate, call the library, print.

Usage errors (bad arguments, bad specs, bad rig files) print one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

__all__ = ["main"]


class UsageError(Exception):
    """Bad input from the user: one line on stderr, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2, no usage dump
        raise UsageError(f"{self.prog}: error: {message}")


def _cmd_objects(args) -> int:
    from lts360.scenes.objects import object_types

    for name, entry in object_types().items():
        print(f"{name:16s} {entry.description}")
        for field, default, alias in entry.parameters():
            al = f" ({alias})" if alias else ""
            print(f"    {field + al:32s} = {default}")
    print("placement (every object): x_mm (x), y_mm (y), tilt_deg, tilt_azimuth_deg")
    return 0


def _atomic_export(mesh, path: Path) -> None:
    path = Path(path)
    if path.suffix.lower() not in (".ply", ".stl", ".obj", ".off", ".glb"):
        raise UsageError(f"--out: unsupported mesh format {path.suffix!r}; use .ply, .stl, .obj, .off or .glb")
    if not path.parent.exists():
        raise UsageError(f"--out: directory {str(path.parent)!r} does not exist")
    tmp = path.with_name(f".{path.name}.tmp{path.suffix}")
    mesh.export(tmp)
    tmp.replace(path)


def _cmd_object(args) -> int:
    from lts360.scenes.objects import build_object

    obj = build_object(args.spec)
    mesh = obj.mesh_world()
    _atomic_export(mesh, Path(args.out))
    print(f"{obj.name}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
          f"watertight={mesh.is_watertight}, volume={mesh.volume:.3f} mm³, "
          f"material={obj.material.name}")
    print(f"spec: {obj.spec}")
    print(f"wrote {args.out}")
    return 0


def _cmd_rig(args) -> int:
    from lts360.experiments.report import format_coverage, format_rig
    from lts360.scenes.coverage import coverage
    from lts360.scenes.rig_io import load_rig

    rig = load_rig(args.rig)
    print(format_rig(rig))
    if args.coverage:
        if not args.radius_mm > 0:
            raise UsageError(f"--radius-mm: must be > 0, got {args.radius_mm}")
        cov = coverage(rig, args.radius_mm, theta_step_deg=args.theta_step_deg,
                       max_incidence_deg=args.max_incidence_deg)
        print(format_coverage(rig, cov))
    return 0


def _set_variant(name: str | None) -> str:
    import mitsuba as mi

    if name is None:
        name = "llvm_ad_mono" if "llvm_ad_mono" in mi.variants() else mi.variants()[0]
    if name not in mi.variants():
        raise UsageError(f"--variant: {name!r} is not compiled into this Mitsuba; choose one of "
                         f"{', '.join(mi.variants())}")
    try:
        mi.set_variant(name)
    except Exception as exc:  # e.g. a CUDA variant on a machine without a GPU
        raise UsageError(f"--variant: {name} cannot run here ({str(exc).splitlines()[0]})") from None
    return name


def _cmd_render(args) -> int:
    import json

    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame, write_frame

    if args.spp < 1 or args.spp > 4096:
        raise UsageError(f"--spp: must be in [1, 4096], got {args.spp}")
    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if not 0 < args.scale <= 1:
        raise UsageError(f"--scale: must be in (0, 1], got {args.scale}")
    if not 0 < args.exposure_fraction <= 1:
        raise UsageError(f"--exposure-fraction: must be in (0, 1], got {args.exposure_fraction}")
    if args.exposure_us is not None and not 0 < args.exposure_us <= 1e7:
        raise UsageError(f"--exposure-us: must be in (0, 1e7], got {args.exposure_us}")
    if args.sections < 1 or args.sections > 10000:
        raise UsageError(f"--sections: must be in [1, 10000], got {args.sections}")
    if args.sections > 1 and not args.pitch_mm > 0:
        raise UsageError(f"--pitch-mm: must be > 0 for a scan, got {args.pitch_mm}")
    rig = load_rig(args.rig)
    obj = build_object(args.object)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out: {str(out)!r} exists and is not a directory")
    variant = _set_variant(args.variant)
    kw = dict(spp=args.spp, seed=args.seed, noise=args.noise, laser_on=args.laser == "on",
              ambient=args.ambient, scale=args.scale, max_bounces=args.max_bounces,
              thin_lens=not args.pinhole, background_z_mm=args.background_z_mm,
              exposure_time_s=None if args.exposure_us is None else args.exposure_us * 1e-6,
              exposure_fraction=args.exposure_fraction)
    if args.sections == 1:
        frame = simulate_frame(rig, obj, z_mm=args.z_mm, **kw)
        write_frame(out, frame)
        print(f"{obj.name} at z = {args.z_mm:g} mm: rendered in {frame.render.seconds:.2f} s "
              f"({variant}, {args.spp} spp), exposure {frame.exposure_time_s * 1e6:.0f} µs, "
              f"max DN {int(frame.image.max())} -> {out}/")
        return 0
    import shutil

    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    zs = args.z_mm + (np.arange(args.sections) - (args.sections - 1) / 2.0) * args.pitch_mm
    sections = []
    for k, z in enumerate(_progress(zs, "sections")):
        frame = simulate_frame(rig, obj, z_mm=float(z), seed=args.seed + k,
                               **{key: v for key, v in kw.items() if key != "seed"})
        write_frame(tmp / f"section_{k:04d}", frame)
        sections.append({"dir": f"section_{k:04d}", "z_mm": float(z), "seed": args.seed + k})
    (tmp / "scan.json").write_text(json.dumps({"object": obj.spec, "pitch_mm": args.pitch_mm,
                                               "sections": sections}, indent=2))
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    print(f"{obj.name}: {args.sections} sections, pitch {args.pitch_mm:g} mm -> {out}/")
    return 0


def _progress(items, desc):
    try:
        from tqdm import tqdm
    except ImportError:  # progress bars are a nicety
        return items
    return tqdm(items, desc=desc, unit="frame")


def _cmd_measure(args) -> int:
    from lts360.recon.calibration.model import load_calibration
    from lts360.recon.triangulation.cloud import write_cloud
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.measure import collect_sections, measure_sections

    if not args.radius_mm > 0 or not args.band_mm > 0 or args.band_mm >= args.radius_mm:
        raise UsageError(f"--radius-mm/--band-mm: need 0 < band < radius, got "
                         f"{args.radius_mm}, {args.band_mm}")
    cal = load_calibration(args.calibration)
    if args.compensate and not any(np.any(v) for v in cal.view_offsets_mm.values()):
        raise UsageError(f"--compensate: {args.calibration} has no view offsets (paper §4.4); "
                         f"make them with `lts360 compensate`")
    grid = CylGrid.from_ranges((args.radius_mm - args.band_mm, args.radius_mm + args.band_mm),
                               theta_step_deg=args.theta_step_deg, r_step_mm=args.r_step_mm)
    sections = collect_sections(args.inputs, pitch_mm=args.pitch_mm)
    out = Path(args.out)
    if not out.parent.exists():
        raise UsageError(f"--out: directory {str(out.parent)!r} does not exist")
    t0 = __import__("time").perf_counter()
    cloud = measure_sections(sections, cal, grid, peak=args.peak, compensate=args.compensate,
                             backend=args.backend, method=args.method,
                             progress=(lambda it: _progress(it, "sections")) if len(sections) > 1
                             else None)
    dt = __import__("time").perf_counter() - t0
    write_cloud(out, cloud)
    valid = cloud.valid
    what = f"peak {args.peak}" if args.method == "inverse" else "classic (Steger 2-D)"
    print(f"{len(sections)} section(s), grid {grid.n_theta} θ × {grid.n_r} r, {what}: "
          f"{int(valid.sum())} valid points of {len(cloud)} θ samples in {dt:.2f} s -> {out}")
    return 0


def _cmd_compensate(args) -> int:
    import dataclasses

    from lts360.recon.calibration.model import load_calibration, save_calibration
    from lts360.recon.calibration.compensation import joint_view_offsets
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.recon.triangulation.measure import collect_sections, read_image

    if not args.radius_mm > 0 or not args.band_mm > 0 or args.band_mm >= args.radius_mm:
        raise UsageError(f"--radius-mm/--band-mm: need 0 < band < radius, got "
                         f"{args.radius_mm}, {args.band_mm}")
    out = Path(args.out)
    if not out.parent.exists():
        raise UsageError(f"--out: directory {str(out.parent)!r} does not exist")
    cal = load_calibration(args.calibration)
    grid = CylGrid.from_ranges((args.radius_mm - args.band_mm, args.radius_mm + args.band_mm),
                               theta_step_deg=args.theta_step_deg, r_step_mm=args.r_step_mm)
    sections = collect_sections(args.inputs, pitch_mm=0.0)
    results = [inverse_triangulate(read_image(s.image_path), cal, grid, peak=args.peak)
               for s in sections]
    # The mirror views are moved onto the direct one, as in the paper.
    offsets = joint_view_offsets(results)
    save_calibration(out, dataclasses.replace(cal, view_offsets_mm=offsets))
    print(f"§4.4 offsets from {len(results)} reference shot(s), one circle each, the views "
          f"shared: " + ", ".join(f"{k} ({1e3 * v[0]:+.1f}, {1e3 * v[1]:+.1f}) µm"
                                  for k, v in sorted(offsets.items())) + f" -> {out}")
    return 0


def _cmd_score(args) -> int:

    from lts360.experiments.score import load_rig_truth, load_truth, score_cloud
    from lts360.recon.triangulation.cloud import read_cloud
    from lts360.simulator.io import write_json

    cloud = read_cloud(args.cloud)
    obj, _ = load_truth(args.truth)
    metrics = score_cloud(cloud, obj, rig_truth=load_rig_truth(args.truth))
    out = Path(args.out)
    if not out.parent.exists():
        raise UsageError(f"--out: directory {str(out.parent)!r} does not exist")
    write_json(out, metrics)
    fmt = lambda v: "—" if v is None else f"{v * 1000:.2f} µm"  # noqa: E731
    print(f"{obj.name}: {metrics['n_points']} points, coverage {metrics['coverage_deg']:.1f}°, "
          f"truth {metrics['truth']}")
    print(f"  rms {fmt(metrics['rms_mm'])}, mean {fmt(metrics['mean_mm'])}, "
          f"max |e| {fmt(metrics['max_abs_mm'])}, p95 {fmt(metrics['p95_mm'])}; normal distance "
          f"to the mesh: rms {fmt(metrics['mesh_distance']['rms_mm'])}")
    if metrics.get("n_spurious"):
        print(f"  {metrics['n_spurious']} spurious points where the true surface is hidden or "
              f"unlit (rms {fmt(metrics['spurious']['rms_mm'])}): counted as missing coverage")
    for view, row in metrics["views"].items():
        print(f"  {view:10s} n={row['n']:6d} rms {fmt(row['rms_mm'])} mean {fmt(row['mean_mm'])} "
              f"coverage {row['coverage_deg']:.1f}°")
    if "radius_bias_mm" in metrics:
        print(f"  fitted diameter {metrics['fitted_diameter_mm']:.5f} mm, radius bias "
              f"{fmt(metrics['radius_bias_mm'])}")
    print(f"wrote {out}")
    return 0


def _board_arg(text: str, name: str):
    """``SXxSYxMM`` (squares along x and y, square side in mm) → Chessboard."""
    from lts360.scenes.targets import Chessboard

    try:
        sx, sy, mm = text.lower().split("x")
        sx, sy, mm = int(sx), int(sy), float(mm)
    except ValueError:
        raise UsageError(f"{name}: expected SQUARESxSQUARESxSIDE_MM such as 7x6x2, got {text!r}") \
            from None
    return Chessboard(squares_x=sx, squares_y=sy, square_mm=mm, margin_mm=max(1.0, mm / 2))


def _cmd_calibrate(args) -> int:
    from lts360.experiments.calibration_run import format_report, run_calibrate

    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if not 1 <= args.spp <= 4096:
        raise UsageError(f"--spp: must be in [1, 4096], got {args.spp}")
    if args.target_spp is not None and not 1 <= args.target_spp <= 4096:
        raise UsageError(f"--target-spp: must be in [1, 4096], got {args.target_spp}")
    if args.f_number is not None and not 0.5 <= args.f_number <= 64:
        raise UsageError(f"--f-number: must be in [0.5, 64], got {args.f_number}")
    if args.camera_model is not None and not 0 <= args.camera_model <= 5:
        raise UsageError(f"--camera-model: must be in [0, 5], got {args.camera_model}")
    if args.camera_poses < 4 or args.mirror_poses < 1 or args.laser_poses < 2:
        raise UsageError("--camera-poses >= 4, --mirror-poses >= 1 and --laser-poses >= 2 needed, "
                         f"got {args.camera_poses}, {args.mirror_poses}, {args.laser_poses}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out: {str(out)!r} exists and is not a directory")
    if args.images is not None:
        if not Path(args.images).is_dir():
            raise UsageError(f"--images: {args.images!r} is not a directory")
    else:
        from lts360.scenes.rig_io import load_rig

        load_rig(args.rig)  # fail early on a bad rig
        _set_variant(args.variant)
    board = _board_arg(args.board, "--board")
    camera_board = None if args.camera_board is None else _board_arg(args.camera_board,
                                                                     "--camera-board")
    report = run_calibrate(out, rig_name=args.rig, noise=args.noise, seed=args.seed,
                           images_dir=args.images, spp=args.spp, n_camera=args.camera_poses,
                           n_mirror=args.mirror_poses, n_laser=args.laser_poses, board=board,
                           camera_board=camera_board, tangential=args.tangential,
                           thin_lens=not args.pinhole, f_number=args.f_number,
                           laser_in_mirror=not args.laser_direct, target_spp=args.target_spp,
                           camera_model_rounds=args.camera_model)
    print(format_report(report))
    print(f"wrote {out}/calibration.json, report.json, fig8.png")
    return 0


def _objects_arg(text: str | None, allowed, default) -> list[str]:
    """``--objects a,b,c`` checked against ``allowed`` (``default`` when not given)."""
    names = text.split(",") if text else list(default)
    for name in names:
        if name not in allowed:
            raise UsageError(f"--objects: unknown object {name!r}; choose from "
                             f"{', '.join(allowed)}")
    return names


def _optional_file(value, option: str):
    if value is not None and not Path(value).is_file():
        raise UsageError(f"{option}: {value!r} is not a file")
    return value


def _study_common(args) -> dict:
    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers: must be >= 1, got {args.workers}")
    if args.workers is not None and args.dask is not None:
        raise UsageError("--workers and --dask exclude each other")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out: {str(out)!r} exists and is not a directory")
    return {"seed": args.seed, "dask_address": args.dask}


def _study_rig(rig: str) -> None:
    from lts360.scenes.rig_io import load_rig

    load_rig(rig)  # fail early on a bad rig


def _check_shots(shots: int) -> None:
    if not 1 <= shots <= 100:
        raise UsageError(f"--compensation-shots: must be in [1, 100], got {shots}")


def _cmd_study_plug_gauge(args) -> int:
    from lts360.experiments.gauge_study import format_gauge_table, run_plug_gauge_study

    common = _study_common(args)
    if not 1 <= args.trials <= 10000:
        raise UsageError(f"--trials: must be in [1, 10000], got {args.trials}")
    _check_shots(args.compensation_shots)
    _optional_file(args.calibration, "--calibration")
    _study_rig(args.rig)
    _set_variant(args.variant)
    table = run_plug_gauge_study(args.out, trials=args.trials, calibration=args.calibration,
                                 noise=args.noise, spp=args.spp, rig=args.rig,
                                 compensation_shots=args.compensation_shots,
                                 workers=args.workers or 1, **common)
    print(format_gauge_table(table))
    print(f"wrote {args.out}/ (table.txt, table.json, plug-gauge.png, trials/results.nc)")
    return 0


def _cmd_study_monte_carlo(args) -> int:
    from lts360.experiments.gauge_study import ensure_calibration
    from lts360.experiments.monte_carlo import format_mc, run_monte_carlo_study

    common = _study_common(args)
    if not 2 <= args.trials <= 10**6:
        raise UsageError(f"--trials: must be in [2, 1000000], got {args.trials}")
    if not 2 <= args.batch <= 10**5 or not 2 <= args.sensitivity_trials <= 10**5:
        raise UsageError("--batch and --sensitivity-trials must be >= 2")
    if not 1 <= args.placements <= 100:
        raise UsageError(f"--placements: must be in [1, 100], got {args.placements}")
    if not 1 <= args.digits <= 4:
        raise UsageError(f"--digits: must be in [1, 4], got {args.digits}")
    _check_shots(args.compensation_shots)
    _optional_file(args.calibration, "--calibration")
    _study_rig(args.rig)
    _set_variant(args.variant)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # The study compensates itself (every trial alike, at its reference placement).
    cal = ensure_calibration(out, args.calibration, rig=args.rig, seed=args.seed,
                             compensate=False)
    summary = run_monte_carlo_study(out, calibration=cal, trials=args.trials, rig=args.rig,
                                    compensate=not args.no_compensate,
                                    compensation_shots=args.compensation_shots,
                                    adaptive=args.adaptive, batch=args.batch, n_dig=args.digits,
                                    sensitivity_trials=args.sensitivity_trials,
                                    placements=args.placements, workers=args.workers, **common)
    print(format_mc(summary))
    print(f"wrote {out}/ (summary.json, monte-carlo.png, mc/batch_*/results.nc)")
    return 0


def _cmd_study_examples(args) -> int:
    from lts360.experiments.examples_study import (PAPER_EXAMPLES, format_examples,
                                                   run_examples_study)

    common = _study_common(args)
    objects = _objects_arg(args.objects, list(PAPER_EXAMPLES), PAPER_EXAMPLES)
    if not 0 < args.section_scale <= 1:
        raise UsageError(f"--section-scale: must be in (0, 1], got {args.section_scale}")
    _optional_file(args.calibration, "--calibration")
    _set_variant(args.variant)
    table = run_examples_study(args.out, objects=objects, noise=args.noise, spp=args.spp,
                               calibration=args.calibration, section_scale=args.section_scale,
                               workers=args.workers or 1, **common)
    print(format_examples(table))
    print(f"wrote {args.out}/ (table.txt, clouds/*.ply, figures/*.png, trials/results.nc)")
    return 0


def _cmd_study_algorithms(args) -> int:
    from lts360.experiments.algorithms import (DEFAULT_OBJECTS, format_algorithms,
                                               run_algorithms_study)
    from lts360.scenes.objects import object_types

    common = _study_common(args)
    objects = _objects_arg(args.objects, list(object_types()), DEFAULT_OBJECTS)
    if not 1 <= args.repeats <= 1000:
        raise UsageError(f"--repeats: must be in [1, 1000], got {args.repeats}")
    _set_variant(args.variant)
    table = run_algorithms_study(args.out, objects=objects, repeats=args.repeats,
                                 workers=args.workers or 1, **common)
    print(format_algorithms(table))
    print(f"wrote {args.out}/ (table.txt, table.json, trials/results.nc)")
    return 0


def _cmd_study_design_space(args) -> int:
    from lts360.experiments.design_space import (format_design_space, parse_range,
                                                 run_design_space_study)

    common = _study_common(args)
    try:
        alpha, beta = parse_range(args.alpha_deg), parse_range(args.beta_deg)
    except ValueError as exc:
        raise UsageError(f"--alpha-deg/--beta-deg: {exc}") from None
    if args.draws == 1 or not 0 <= args.draws <= 10000:
        raise UsageError(f"--draws: must be 0 (geometry only) or in [2, 10000], got {args.draws}")
    if not 0 < args.scale <= 1:
        raise UsageError(f"--scale: must be in (0, 1], got {args.scale}")
    _set_variant(args.variant)
    summary = run_design_space_study(args.out, alpha_deg=alpha, beta_deg=beta, draws=args.draws,
                                     spp=args.spp, scale=args.scale, workers=args.workers or 1,
                                     **common)
    print(format_design_space(summary))
    print(f"wrote {args.out}/ (README.md, summary.json, grid.nc, design-space-*.png)")
    return 0


def _cmd_demo(args) -> int:
    from lts360.experiments.demo import run_demo

    if not args.radius_mm > 0:
        raise UsageError(f"--radius-mm: must be > 0, got {args.radius_mm}")
    render = not args.no_render
    if render:
        _set_variant(args.variant)
    if not 1 <= args.gauge_trials <= 1000:
        raise UsageError(f"--gauge-trials: must be in [1, 1000], got {args.gauge_trials}")
    run_demo(Path(args.out), radius_mm=args.radius_mm, render=render, paper=not args.quick,
             gauge_trials=args.gauge_trials, seed=args.seed)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="lts360", description="360° laser triangulation with mirrors: simulation "
                "and reconstruction testbed.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    s = sub.add_parser("objects", help="list every object with its parameters and defaults")
    s.set_defaults(func=_cmd_objects)

    s = sub.add_parser("object", help="write an object's ground-truth mesh (world frame, mm)")
    s.add_argument("spec", help="NAME[:key=value,...], e.g. plug-gauge:d=19.9987,x=0.2,tilt_deg=1")
    s.add_argument("--out", required=True, help="output mesh file (.ply, .stl, .obj, .off, .glb)")
    s.set_defaults(func=_cmd_object)

    s = sub.add_parser("rig", help="describe a rig and its coverage")
    s.add_argument("rig", nargs="?", default="paper", help="preset name (paper) or TOML file")
    s.add_argument("--coverage", action="store_true", help="print per-view θ windows and total coverage")
    s.add_argument("--radius-mm", type=float, default=10.0, help="section radius (default 10)")
    s.add_argument("--theta-step-deg", type=float, default=0.1, help="θ sampling (default 0.1°)")
    s.add_argument("--max-incidence-deg", type=float, default=80.0,
                   help="largest usable incidence angle of camera and laser (default 80°)")
    s.set_defaults(func=_cmd_rig)

    s = sub.add_parser("render", help="render a frame (or a scan) of an object in the rig")
    s.add_argument("--object", required=True, help="object SPEC, e.g. plug-gauge or cable-8:x=0.3")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--rig", default="paper", help="preset name or TOML file (default paper)")
    s.add_argument("--z-mm", type=float, default=0.0, help="section height on the object (mm)")
    s.add_argument("--noise", choices=("none", "realistic"), default="none")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--spp", type=int, default=16, help="samples per pixel (default 16)")
    s.add_argument("--variant", default=None,
                   help="Mitsuba variant: llvm_ad_mono (default), cuda_ad_mono, scalar_rgb, ...")
    s.add_argument("--laser", choices=("on", "off"), default="on")
    s.add_argument("--ambient", choices=("off", "dim", "bright"), default="off")
    s.add_argument("--scale", type=float, default=1.0, help="image scale in (0, 1]")
    s.add_argument("--max-bounces", type=int, choices=(0, 1, 2, 3), default=2,
                   help="mirror reflections followed on camera and laser paths (default 2)")
    s.add_argument("--pinhole", action="store_true", help="pinhole instead of the thin lens")
    s.add_argument("--exposure-us", type=float, default=None,
                   help="fixed exposure time (default: auto-exposure)")
    s.add_argument("--exposure-fraction", type=float, default=0.8,
                   help="auto-exposure target: brightest stripe pixels at this fraction of full scale")
    s.add_argument("--background-z-mm", type=float, default=None,
                   help="add a matte black base plate at this height (default: none)")
    s.add_argument("--sections", type=int, default=1, help="render a scan of N sections")
    s.add_argument("--pitch-mm", type=float, default=0.0, help="stage pitch of a scan (mm)")
    s.set_defaults(func=_cmd_render)

    s = sub.add_parser("measure", help="inverse triangulation of frames, scans or images")
    s.add_argument("inputs", nargs="+", help="frame directories, scan directories or image files")
    s.add_argument("--calibration", required=True,
                   help="calibration.json, or a rendered frame's frame.json (the true rig)")
    s.add_argument("--out", required=True, help="cloud.ply")
    s.add_argument("--method", choices=("inverse", "classic"), default="inverse",
                   help="inverse triangulation (paper §3.2) or the classical image-space baseline")
    s.add_argument("--peak", choices=("centroid", "gauss", "steger"), default="centroid")
    s.add_argument("--theta-step-deg", type=float, default=0.1)
    s.add_argument("--r-step-mm", type=float, default=0.005)
    s.add_argument("--radius-mm", type=float, default=10.0, help="nominal radius (default 10)")
    s.add_argument("--band-mm", type=float, default=2.0, help="radial search band ± (default 2)")
    s.add_argument("--pitch-mm", type=float, default=None, help="stage pitch for bare images")
    s.add_argument("--compensate", action="store_true",
                   help="apply the calibration's residual compensation (paper §4.4)")
    s.add_argument("--backend", choices=("auto", "numpy", "llvm", "cuda"), default="auto",
                   help="auto: the Dr.Jit kernel for the centroid, numpy otherwise")
    s.set_defaults(func=_cmd_measure)

    s = sub.add_parser("compensate", help="residual compensation (paper §4.4): the mirror "
                       "views' offsets from images of a round reference, into a calibration")
    s.add_argument("inputs", nargs="+", help="frame directories, scan directories or image "
                   "files of one round reference section (several: shots fitted together)")
    s.add_argument("--calibration", required=True, help="calibration.json to compensate")
    s.add_argument("--out", required=True, help="the compensated calibration.json")
    s.add_argument("--peak", choices=("centroid", "gauss", "steger"), default="centroid")
    s.add_argument("--theta-step-deg", type=float, default=0.1)
    s.add_argument("--r-step-mm", type=float, default=0.005)
    s.add_argument("--radius-mm", type=float, default=10.0,
                   help="the reference's nominal radius (default 10)")
    s.add_argument("--band-mm", type=float, default=1.0, help="radial search band ± (default 1)")
    s.set_defaults(func=_cmd_compensate)

    s = sub.add_parser("score", help="score a measured cloud against the truth of rendered frames")
    s.add_argument("cloud", help="cloud.ply written by `lts360 measure`")
    s.add_argument("--truth", required=True, help="frame or scan directory written by `lts360 render`")
    s.add_argument("--out", required=True, help="metrics.json")
    s.set_defaults(func=_cmd_score)

    s = sub.add_parser("calibrate", help="calibrate camera, mirrors and laser plane from "
                       "chessboard images (rendered, or yours with --images)")
    s.add_argument("--out", required=True, help="output directory (calibration.json, report.json, "
                   "fig8.png, images/)")
    s.add_argument("--rig", default="paper", help="rig to render: 'paper' or a TOML file")
    s.add_argument("--noise", choices=("none", "realistic"), default="none")
    s.add_argument("--seed", type=int, default=0, help="seeds the poses, the renderer and the noise")
    s.add_argument("--images", default=None, help="a folder of real images with manifest.json: "
                   "nothing is rendered")
    s.add_argument("--spp", type=int, default=64, help="samples per pixel of the rendered images")
    s.add_argument("--target-spp", type=int, default=None, help="samples per pixel of the "
                   "mirror and laser shots (default: --spp; their small board's defocused "
                   "edges are where render noise counts)")
    s.add_argument("--camera-poses", type=int, default=30)
    s.add_argument("--camera-model", type=int, default=None, metavar="ROUNDS",
                   help="rounds of Zhang's method on the camera boards' corners from their "
                   "image model (default 0: on the detected corners)")
    s.add_argument("--mirror-poses", type=int, default=6, help="per mirror")
    s.add_argument("--laser-poses", type=int, default=6)
    s.add_argument("--laser-direct", action="store_true", help="laser boards seen directly only "
                   "(pose from PnP) instead of directly and in a mirror (pose from both views)")
    s.add_argument("--board", default="7x6x2", help="mirror/laser board: squares x, squares y, "
                   "side mm (paper: 7x6x2)")
    s.add_argument("--camera-board", default=None, help="camera board (default 9x7x8)")
    s.add_argument("--tangential", action="store_true", help="estimate the tangential "
                   "distortion p1, p2 as well (default: k1, k2 only)")
    s.add_argument("--pinhole", action="store_true", help="render the images without depth of "
                   "field (the limit of a fully stopped-down lens)")
    s.add_argument("--f-number", type=float, default=None, help="aperture of the calibration "
                   "images (default: the rig's; stopping down sharpens the small boards)")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_mono)")
    s.set_defaults(func=_cmd_calibrate)

    s = sub.add_parser("study", help="the studies: plug-gauge, examples, design-space, "
                       "monte-carlo, algorithms")
    studies = s.add_subparsers(dest="study", metavar="STUDY", parser_class=_Parser)
    studies.required = True

    def study_parser(name, help_text):
        q = studies.add_parser(name, help=help_text)
        q.add_argument("--out", required=True, help="output directory (results, figures, README)")
        q.add_argument("--seed", type=int, default=0)
        q.add_argument("--workers", type=int, default=None, help="local processes")
        q.add_argument("--dask", default=None, metavar="ADDRESS",
                       help="run the trials on a Dask distributed scheduler")
        q.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_mono)")
        return q

    q = study_parser("plug-gauge", "paper §4.5: the gauge placed N times, measured with an "
                     "estimated calibration; the paper's table beside ours")
    q.add_argument("--trials", type=int, default=10)
    q.add_argument("--calibration", default=None, help="calibration.json (default: calibrate "
                   "from rendered images into OUT/calibration/)")
    q.add_argument("--noise", choices=("none", "realistic"), default="realistic")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--rig", default="paper", help="rig to render: 'paper' or a TOML file (the "
                   "one the calibration is of)")
    q.add_argument("--compensation-shots", type=int, default=1, metavar="K",
                   help="images of the gauge (turned between them) the §4.4 compensation is "
                   "fitted to (default 1, as the paper)")
    q.set_defaults(func=_cmd_study_plug_gauge)

    q = study_parser("monte-carlo", "GUM Supplement 1 Monte Carlo of the gauge radius, GUM "
                     "budget, sensitivity ranking, speckle limit")
    q.add_argument("--calibration", default=None, help="calibration.json with uncertainties "
                   "(default: calibrate from rendered images into OUT/calibration/)")
    q.add_argument("--trials", type=int, default=1000, help="M for the fixed-M procedure")
    q.add_argument("--adaptive", action="store_true", help="JCGM 101 §7.9 adaptive procedure")
    q.add_argument("--digits", type=int, default=2, help="significant digits of u(y) the "
                   "adaptive procedure must stabilise")
    q.add_argument("--batch", type=int, default=100)
    q.add_argument("--sensitivity-trials", type=int, default=50,
                   help="trials per input in the one-at-a-time runs")
    q.add_argument("--placements", type=int, default=8, help="rendered gauge placements")
    q.add_argument("--no-compensate", action="store_true", help="no §4.4 compensation")
    q.add_argument("--compensation-shots", type=int, default=1, metavar="K",
                   help="images of the reference placement each §4.4 compensation is fitted "
                   "to (default 1, as the paper)")
    q.add_argument("--rig", default="paper", help="rig to render: 'paper' or a TOML file (the "
                   "one the calibration is of)")
    q.set_defaults(func=_cmd_study_monte_carlo)

    q = study_parser("examples", "paper §4.6: the eight objects scanned with the paper's "
                     "sections and pitch, clouds, figures, error table")
    q.add_argument("--objects", default=None, help="comma-separated subset (default: all eight)")
    q.add_argument("--noise", choices=("none", "realistic"), default="realistic")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--calibration", default=None, help="measure with this calibration "
                   "(default: the frames' true one)")
    q.add_argument("--section-scale", type=float, default=1.0,
                   help="fraction of the paper's sections to scan (quick looks)")
    q.set_defaults(func=_cmd_study_examples)

    q = study_parser("design-space", "α/β sweep: coverage, overlap, multiple reflections, "
                     "Monte Carlo radius uncertainty, heat maps, optimum")
    q.add_argument("--alpha-deg", default="20:70:5", help="START:STOP:STEP (inclusive) or a value")
    q.add_argument("--beta-deg", default="60:120:5", help="START:STOP:STEP (inclusive) or a value")
    q.add_argument("--draws", type=int, default=16, help="noise/speckle draws per rig (0: "
                   "geometry only)")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--scale", type=float, default=1.0, help="image scale (quick looks)")
    q.set_defaults(func=_cmd_study_design_space)

    q = study_parser("algorithms", "inverse vs classic triangulation and the three detectors "
                     "on the same images: bias, std, coverage, time")
    q.add_argument("--objects", default=None, help="comma-separated (default: plug-gauge, "
                   "alu-pipe, grooved-shaft, cable-8, cube)")
    q.add_argument("--repeats", type=int, default=3, help="noise draws per object and level")
    q.set_defaults(func=_cmd_study_algorithms)

    s = sub.add_parser("demo", help="run the main job: rig, coverage, objects, figures")
    s.add_argument("--out", default="lts360-demo", help="output directory (default ./lts360-demo)")
    s.add_argument("--radius-mm", type=float, default=10.0, help="section radius for the coverage")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_mono)")
    s.add_argument("--no-render", action="store_true", help="skip the rendered frames")
    s.add_argument("--quick", action="store_true", help="skip the calibration and the "
                   "plug-gauge study (a few seconds instead of minutes)")
    s.add_argument("--gauge-trials", type=int, default=10, help="plug-gauge placements")
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=_cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    from lts360.scenes.rig import RigError

    try:
        args = build_parser().parse_args(argv)
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(str(exc) if str(exc).startswith("lts360") else f"lts360: error: {exc}", file=sys.stderr)
        return 2
    except (RigError, ValueError, FileNotFoundError) as exc:
        print(f"lts360: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)


if __name__ == "__main__":
    sys.exit(main())
