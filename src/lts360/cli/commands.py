"""The single-job commands: objects, object, rig, render, measure, compensate, score, calibrate,
inspect."""

from __future__ import annotations

import shlex
import sys
import time
from pathlib import Path

import numpy as np

from lts360.cli.usage import UsageError, _progress, _set_variant
from lts360.folders import (
    FRAME_FILE,
    frame_file,
    is_frame,
    is_scan,
    section_dir_name,
    section_dirs,
    write_scan_meta,
)
from lts360.simulator.render import MAX_SPP


def cmd_objects(args) -> int:
    from lts360.scenes.objects import object_types

    for name, entry in object_types().items():
        print(f"{name:16s} {entry.description}")
        for field, default, alias in entry.parameters():
            al = f" ({alias})" if alias else ""
            shown = "(required: your file)" if entry.from_file and field == "path" else default
            print(f"    {field + al:32s} = {shown}")
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


def cmd_object(args) -> int:
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


def cmd_rig(args) -> int:
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


def cmd_render(args) -> int:

    from lts360.scenes.objects import build_object
    from lts360.scenes.objects.part import check_in_field
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame, write_frame

    if not 1 <= args.spp <= MAX_SPP:
        raise UsageError(f"--spp: must be in [1, {MAX_SPP}], got {args.spp}")
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
    acq = _acquisition(args)
    if acq is None and args.sections > 1 and not args.pitch_mm > 0:
        raise UsageError(f"--pitch-mm: must be > 0 for a scan, got {args.pitch_mm}")
    if args.roughness is not None and not 0 < args.roughness <= 1:
        raise UsageError(f"--roughness: must be in (0, 1], got {args.roughness}")
    rig = load_rig(args.rig)
    obj = build_object(args.object)
    if args.roughness is not None:
        import dataclasses

        obj = dataclasses.replace(obj, material=dataclasses.replace(
            obj.material, roughness_alpha=args.roughness))
    if obj.notes.get("part"):  # a user's part: it must fit between the mirrors
        check_in_field(obj, rig)
    from lts360.scenes.materials import resolve_max_scatter

    args.max_scatter = resolve_max_scatter(args.max_scatter, obj.material)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out: {str(out)!r} exists and is not a directory")
    variant = _set_variant(args.variant)
    kw = dict(spp=args.spp, seed=args.seed, noise=args.noise, laser_on=args.laser == "on",
              ambient=args.ambient, scale=args.scale, max_bounces=args.max_bounces,
              max_scatter=args.max_scatter,
              thin_lens=not args.pinhole, background_z_mm=args.background_z_mm,
              exposure_time_s=None if args.exposure_us is None else args.exposure_us * 1e-6,
              exposure_fraction=args.exposure_fraction,
              support=args.support)
    if acq is not None:
        return _render_moving(args, rig, obj, acq, out, variant)
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
    from lts360.simulator.reuse import SceneCache

    zs = args.z_mm + (np.arange(args.sections) - (args.sections - 1) / 2.0) * args.pitch_mm
    sections = []
    scenes = SceneCache()  # one scene for the scan: each section moves the object
    for k, z in enumerate(_progress(zs, "sections")):
        frame = simulate_frame(rig, obj, z_mm=float(z), seed=args.seed + k, scenes=scenes,
                               **{key: v for key, v in kw.items() if key != "seed"})
        write_frame(tmp / section_dir_name(k), frame)
        sections.append({"dir": section_dir_name(k), "z_mm": float(z), "seed": args.seed + k})
    write_scan_meta(tmp, {"object": obj.spec, "pitch_mm": args.pitch_mm, "sections": sections})
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    print(f"{obj.name}: {args.sections} sections, pitch {args.pitch_mm:g} mm -> {out}/")
    return 0


def _acquisition(args):
    """The line's acquisition from ``render``'s motion options, or ``None`` for a still frame."""
    from lts360.scenes.motion import Acquisition, Motion, Shutter, Trigger

    moving = (args.speed_mm_s != 0 or args.vibration_mm is not None or args.rotation_deg_s != 0
              or args.shutter != "global" or args.profile_rate_hz is not None
              or args.encoder_pitch_mm is not None)
    if not moving:
        return None
    if args.exposure_us is None:
        raise UsageError("--exposure-us: a moving frame needs a fixed exposure")
    amp = (0.0, 0.0)
    if args.vibration_mm is not None:
        try:
            amp = tuple(float(v) for v in args.vibration_mm.split(","))
        except ValueError:
            raise UsageError(f"--vibration-mm: expected AX,AY in mm, got {args.vibration_mm!r}")
    if args.sections > 1 and args.profile_rate_hz is None and args.encoder_pitch_mm is None:
        raise UsageError("--sections: a moving scan needs --profile-rate-hz or --encoder-pitch-mm")
    try:
        trigger = (None if args.profile_rate_hz is None and args.encoder_pitch_mm is None
                   else Trigger(args.profile_rate_hz, args.encoder_pitch_mm,
                                args.jitter_us * 1e-6))
        return Acquisition(args.exposure_us * 1e-6,
                           shutter=Shutter(args.shutter, args.line_time_us * 1e-6),
                           motion=Motion(args.speed_mm_s, amp, args.vibration_hz,
                                         rotation_rate_deg_s=args.rotation_deg_s,
                                         vibration_kind=args.vibration_kind,
                                         vibration_seed=args.vibration_seed),
                           trigger=trigger)
    except ValueError as exc:
        raise UsageError(f"motion: {exc}")


def _render_moving(args, rig, obj, acq, out: Path, variant: str) -> int:
    """``render`` of a moving object: one frame, or a scan triggered by ``acq.trigger``."""
    import shutil

    from lts360.simulator.frame import write_frame
    from lts360.simulator.motion import simulate_moving_frame

    if args.step_px <= 0:
        raise UsageError(f"--step-px: must be > 0, got {args.step_px}")
    n = args.sections
    times = (np.zeros(1) if acq.trigger is None
             else acq.trigger.times_s(n, acq.motion.speed_mm_s, rng=args.seed))
    kw = dict(spp=args.spp, noise=args.noise, scale=args.scale, max_bounces=args.max_bounces,
              thin_lens=not args.pinhole, step_px=args.step_px, z_mm=args.z_mm,
              max_scatter=args.max_scatter)
    try:  # everything checked on the first frame before anything is written
        frames = [simulate_moving_frame(rig, obj, acq, t_trigger_s=float(times[0]),
                                        seed=args.seed, **kw)]
        if n > 1:  # the last one's feed too
            last_cut = args.z_mm - acq.motion.speed_mm_s * (times[-1] + acq.readout_s(
                frames[0].image.shape[0]))
            lo, hi = obj.measured_zone_z_mm
            if not lo <= last_cut <= hi:
                raise ValueError(f"the scan's feed reaches z = {last_cut:.3g} mm of the object, "
                                 f"off its measured zone [{lo:.3g}, {hi:.3g}] mm")
    except ValueError as exc:
        raise UsageError(f"motion: {exc}")
    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    if n == 1:
        write_frame(tmp, frames[0])
    else:
        sections = []
        for k, t in enumerate(_progress(times, "sections")):
            frame = frames[0] if k == 0 else simulate_moving_frame(
                rig, obj, acq, t_trigger_s=float(t), seed=args.seed + k, **kw)
            write_frame(tmp / section_dir_name(k), frame)
            sections.append({"dir": section_dir_name(k), "t_trigger_s": float(t),
                             "z_mm": float(args.z_mm - acq.motion.speed_mm_s * t),
                             "seed": args.seed + k})
        write_scan_meta(tmp, {"object": obj.spec, "acquisition": acq.to_dict(),
                              "sections": sections})
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    m = frames[0].truth["motion"]
    print(f"{obj.name} moving ({acq.shutter.kind} shutter, {acq.motion.speed_mm_s:g} mm/s): "
          f"{n} frame(s), {m['renders']} sub-renders of the first ({variant}, {args.spp} spp) "
          f"-> {out}/")
    return 0


def _scan_calibration_hint(path) -> None:
    """A calibration path that does not exist inside a scan folder (``SCAN/frame.json``): name
    the file to use, since each section of a rendered scan holds its own ``frame.json``."""
    p = Path(path)
    if p.exists() or not is_scan(p.parent):
        return
    first = [frame_file(d) for d in section_dirs(p.parent) if is_frame(d)]
    if first:
        raise UsageError(f"--calibration: {p} does not exist; a scan folder holds one "
                         f"{FRAME_FILE} per section (the same rig): use {first[0]}")


def cmd_measure(args) -> int:
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.acceptance import refusal, section_coverage
    from lts360.recon.triangulation.band import DEFAULT_FIXED_HALF_WIDTH_MM, DEFAULT_FIXED_RADIUS_MM
    from lts360.recon.triangulation.cloud import write_cloud
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.measure import (
        collect_sections,
        measure_sections,
        measure_sections_following,
    )

    if not 0.0 <= args.min_coverage <= 1.0:
        raise UsageError(f"--min-coverage: must be in [0, 1], got {args.min_coverage}")
    # No --radius-mm: the band is found from the image (inverse method); the classic baseline
    # keeps the fixed default band.
    follow = args.radius_mm is None and args.method == "inverse"
    if follow:
        if args.band_mm is not None and not 0 < args.band_mm <= 10:
            raise UsageError(f"--band-mm: must be in (0, 10] about the found profile, got "
                             f"{args.band_mm}")
    else:
        radius = DEFAULT_FIXED_RADIUS_MM if args.radius_mm is None else args.radius_mm
        band_mm = DEFAULT_FIXED_HALF_WIDTH_MM if args.band_mm is None else args.band_mm
        if not radius > 0 or not band_mm > 0 or band_mm >= radius:
            raise UsageError(f"--radius-mm/--band-mm: need 0 < band < radius, got "
                             f"{radius}, {band_mm}")
    if args.continuity_k is not None and not 0 < args.continuity_k <= 100:
        raise UsageError(f"--continuity-k: must be in (0, 100], got {args.continuity_k}")
    if not 0 < args.theta_step_deg <= 10:
        raise UsageError(f"--theta-step-deg: must be in (0, 10], got {args.theta_step_deg}")
    if not 0 < args.r_step_mm <= 0.1:
        raise UsageError(f"--r-step-mm: must be in (0, 0.1], got {args.r_step_mm}")
    if args.twin_corners == "on" and args.bias_model != "twin":
        raise UsageError("--twin-corners on: only with --bias-model twin (the corners are "
                         "restored in the twin)")
    _scan_calibration_hint(args.calibration)
    cal = load_calibration(args.calibration)
    if args.compensate and not any(np.any(v) for v in cal.view_offsets_mm.values()):
        raise UsageError(f"--compensate: {args.calibration} has no view offsets (paper §4.4); "
                         f"make them with `lts360 compensate`")
    twin = None
    if args.bias_model == "twin":
        twin = _twin_corrector(args, cal)
    sections = collect_sections(args.inputs, pitch_mm=args.pitch_mm)
    out = Path(args.out)
    if not out.parent.exists():
        raise UsageError(f"--out: directory {str(out.parent)!r} does not exist")
    progress = (lambda it: _progress(it, "sections")) if len(sections) > 1 else None
    t0 = time.perf_counter()
    searched = None
    if follow:
        cloud, grid, log = measure_sections_following(
            sections, cal, theta_step_deg=args.theta_step_deg, r_step_mm=args.r_step_mm,
            half_width_mm=args.band_mm, peak=args.peak, compensate=args.compensate,
            backend=args.backend, progress=progress, continuity_k=args.continuity_k,
            reject=args.reject == "on", correct=twin, multipeak=args.multipeak == "on")
        searched = log.describe()
    else:
        grid = CylGrid.from_ranges((radius - band_mm, radius + band_mm),
                                   theta_step_deg=args.theta_step_deg, r_step_mm=args.r_step_mm)
        cloud = measure_sections(sections, cal, grid, peak=args.peak, compensate=args.compensate,
                                 backend=args.backend, method=args.method, progress=progress,
                                 continuity_k=args.continuity_k, reject=args.reject == "on",
                                 correct=twin, multipeak=args.multipeak == "on")
    dt = time.perf_counter() - t0
    coverages = section_coverage(cloud, grid, n_sections=len(sections),
                                 windows_in_cloud=args.method == "inverse")
    refused = refusal(coverages, grid, min_fraction=args.min_coverage, searched_band=searched)
    valid = cloud.valid
    if not valid.any():  # nothing to write: an empty cloud is no measurement
        print(f"lts360: measure: {refused}; nothing written", file=sys.stderr)
        return 3
    comments = [] if twin is None else _twin_comments(twin)
    if args.compensate and cal.master:  # the mastering's u, for inspect's U
        comments += [f"lts360 master {v} u_radius_um {1e3 * u:.4f}"
                     for v, u in sorted(cal.master.get("u_radius_mm", {}).items())]
    write_cloud(out, cloud, comments=comments)
    what = f"peak {args.peak}" if args.method == "inverse" else "classic (Steger 2-D)"
    print(f"{len(sections)} section(s), grid {grid.n_theta} θ × {grid.n_r} r, {what}: "
          f"{int(valid.sum())} valid points of {len(cloud)} θ samples in {dt:.2f} s -> {out}")
    if follow:
        print(f"  {searched}: {len(log.searched)} coarse pass(es) ({log.coarse_s:.2f} s), "
              f"band planning {log.plan_s:.2f} s, fine measurement {log.fine_s:.2f} s")
    flagged = _flag_counts(cloud)
    if flagged:
        print("  not measured: " + ", ".join(f"{n} {name}" for name, n in flagged))
    if twin is not None:
        print("  " + twin.log.describe())
        if len(sections) == 1:
            print("  twin: one section, so its twin is a straight prism: a surface curved along "
                  "the axis (a waviness) is not modelled; measure a scan to shape it")
        skipped = [k for k, s in enumerate(twin.log.sections) if s["skipped"]]
        if skipped:
            print(f"  twin: {len(skipped)} section(s) not corrected (too few points): "
                  f"{skipped[:10]}")
    if refused is not None:
        print(f"lts360: measure: {refused}; the cloud is written with its flags", file=sys.stderr)
        return 3
    return 0


def _twin_u_mm(cloud_path) -> float | None:
    """A twin-corrected cloud's radial u from the correction's inputs (mm): the points-weighted
    RMS over the views of ``u_inputs_um``; ``None`` for a cloud without a twin record."""
    from lts360.recon.triangulation.cloud import read_cloud_twin

    rec = read_cloud_twin(cloud_path)
    rows = [(v.get("corrected", 0.0), v.get("u_inputs_um", float("nan"))) for v in rec.values()]
    rows = [(n, u) for n, u in rows if n > 0 and np.isfinite(u)]
    if not rows:
        return None
    n, u = np.array(rows).T
    return float(1e-3 * np.sqrt(np.sum(n * u * u) / np.sum(n)))


def _twin_corrector(args, cal):
    """The ``--bias-model twin`` hook, or a usage error naming what is wrong."""
    from lts360.twin import TwinCorrector
    from lts360.twin.debias import MAX_AXIAL_REACH_MM
    from lts360.twin.rig import twin_design

    if args.method != "inverse":
        raise UsageError("--bias-model twin: needs the inverse method (the twin is measured "
                         "with the real image's plan)")
    if not 1 <= args.twin_spp <= MAX_SPP:
        raise UsageError(f"--twin-spp: must be in [1, {MAX_SPP}], got {args.twin_spp}")
    if not 0 <= args.twin_axial_mm <= MAX_AXIAL_REACH_MM:
        raise UsageError(f"--twin-axial-mm: must be in [0, {MAX_AXIAL_REACH_MM:g}], got "
                         f"{args.twin_axial_mm}")
    try:
        return TwinCorrector(cal, twin_design(cal, args.twin_rig), material=args.twin_material,
                             spp=args.twin_spp, axial_reach_mm=args.twin_axial_mm,
                             corners=getattr(args, "twin_corners", "off") == "on")
    except (ValueError, KeyError, FileNotFoundError) as exc:
        raise UsageError(f"--bias-model twin: {exc}") from None


def _twin_comments(twin) -> list[str]:
    """PLY header lines: the bias the twin removed per view (µm) and its render uncertainty."""
    return [f"lts360 twin {name} bias_um {v['mean_bias_um']:+.3f} corrected {v['n_corrected']} "
            f"uncorrected {v['n_uncorrected']} u_render_um {v['u_render_um']:.3f} "
            f"u_inputs_um {v['u_inputs_um']:.3f}"
            for name, v in twin.log.summary().items()]


def _flag_counts(cloud) -> list[tuple[str, int]]:
    """(name, count) of the quality flags of the cloud's invalid rows, largest first."""
    from lts360.recon.triangulation.peaks import Quality

    q = np.asarray(cloud.quality)[~cloud.valid]
    codes, counts = np.unique(q, return_counts=True)
    names = {int(v): v.name for v in Quality}
    rows = [(names.get(int(c), f"code {int(c)}"), int(n)) for c, n in zip(codes, counts)]
    return sorted(rows, key=lambda t: -t[1])


def _number_list(text: str, name: str) -> list[float]:
    try:
        return [float(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"{name}: expected numbers separated by commas, got {text!r}") from None


def _master_args(args, cal) -> tuple[list[float], list[float]] | None:
    """``--master-diameter-mm`` / ``--master-u-mm`` checked against the rig the calibration
    records (the paper preset without a record): None without masters."""
    if args.master_diameter_mm is None:
        if args.master_u_mm is not None:
            raise UsageError("--master-u-mm: give the masters' diameters (--master-diameter-mm)")
        return None
    from lts360.scenes.rig_io import load_rig
    from lts360.twin.rig import recorded_rig

    D = _number_list(args.master_diameter_mm, "--master-diameter-mm")
    rig = recorded_rig(cal) or load_rig("paper")
    d_max = 2.0 * rig.design.max_object_radius_mm if rig.design is not None else 40.0
    if not 1 <= len(D) <= 4:
        raise UsageError(f"--master-diameter-mm: one to four diameters, got {len(D)}")
    for d in D:
        if not (np.isfinite(d) and 0 < d <= d_max):
            raise UsageError(f"--master-diameter-mm: each must be in (0, {d_max:g}] mm (rig "
                             f"{rig.name!r}'s objects), got {d:g}")
    from lts360.recon.calibration.compensation import MIN_MASTER_SPREAD_MM

    ds = sorted(D)
    if len(D) > 1 and min(b - a for a, b in zip(ds, ds[1:])) < MIN_MASTER_SPREAD_MM:
        raise UsageError(f"--master-diameter-mm: the masters must differ by at least "
                         f"{MIN_MASTER_SPREAD_MM:g} mm (two of the same diameter set no scale), "
                         f"got {args.master_diameter_mm}")
    U = [0.0] * len(D) if args.master_u_mm is None else _number_list(args.master_u_mm,
                                                                      "--master-u-mm")
    if len(U) == 1 and len(D) > 1:
        U = U * len(D)
    if len(U) != len(D) or not all(np.isfinite(u) and 0 <= u <= 0.1 for u in U):
        raise UsageError(f"--master-u-mm: one u in [0, 0.1] mm per master diameter (or one for "
                         f"all), got {args.master_u_mm}")
    return D, U


def _twin_corrected_raw(result, cal, grid, args):
    """A reference shot's raw radii with its line-centre bias removed by its twin."""
    from lts360.twin import TwinCorrector, twin_corrected_raw
    from lts360.twin.rig import twin_design

    try:
        twin = TwinCorrector(cal, twin_design(cal, args.twin_rig), input_u=None)
    except (ValueError, KeyError, FileNotFoundError) as exc:
        raise UsageError(f"--bias-model twin: {exc}") from None
    fixed = twin_corrected_raw(result, cal, grid, twin, peak=args.peak)
    print("  reference " + twin.log.describe())
    return fixed


def cmd_compensate(args) -> int:
    import dataclasses

    from lts360.geometry.fit import fit_circle
    from lts360.recon.calibration.compensation import joint_view_offsets, master_fit
    from lts360.recon.images import read_image
    from lts360.recon.model import load_calibration, save_calibration
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.recon.triangulation.measure import collect_sections

    if not args.radius_mm > 0 or not args.band_mm > 0 or args.band_mm >= args.radius_mm:
        raise UsageError(f"--radius-mm/--band-mm: need 0 < band < radius, got "
                         f"{args.radius_mm}, {args.band_mm}")
    out = Path(args.out)
    if not out.parent.exists():
        raise UsageError(f"--out: directory {str(out.parent)!r} does not exist")
    cal = load_calibration(args.calibration)
    masters = _master_args(args, cal)
    if masters is None and args.bias_model != "none":
        raise UsageError("--bias-model: only with masters (--master-diameter-mm): the §4.4 "
                         "offsets of the paper are fitted on the raw views")
    sections = collect_sections(args.inputs, pitch_mm=0.0)

    def grid_about(radius):
        if not args.band_mm < radius:
            raise UsageError(f"--band-mm: must be below the reference's radius {radius:g} mm, "
                             f"got {args.band_mm:g}")
        return CylGrid.from_ranges((radius - args.band_mm, radius + args.band_mm),
                                   theta_step_deg=args.theta_step_deg, r_step_mm=args.r_step_mm)

    if masters is None:
        grid = grid_about(args.radius_mm)
        results = [inverse_triangulate(read_image(s.image_path), cal, grid, peak=args.peak)
                   for s in sections]
        # The mirror views are moved onto the direct one, as in the paper.
        offsets = joint_view_offsets(results)
        save_calibration(out, dataclasses.replace(cal, view_offsets_mm=offsets))
        print(f"§4.4 offsets from {len(results)} reference shot(s), one circle each, the views "
              f"shared: " + ", ".join(f"{k} ({1e3 * v[0]:+.1f}, {1e3 * v[1]:+.1f}) µm"
                                      for k, v in sorted(offsets.items())) + f" -> {out}")
        return 0
    D, U = masters
    results, shot_d, shot_u = [], [], []
    for s in sections:
        img = read_image(s.image_path)
        if len(D) == 1:
            k = 0
        else:  # which master: a coarse look over all of them
            lo, hi = min(D) / 2 - args.band_mm, max(D) / 2 + args.band_mm
            coarse = inverse_triangulate(img, cal, CylGrid.from_ranges(
                (max(lo, 0.5), hi), theta_step_deg=1.0, r_step_mm=0.02), peak=args.peak)
            pts = np.concatenate([v.points_meas_mm[v.valid, :2]
                                  for v in coarse.views.values()])
            if len(pts) < 10:
                raise UsageError(f"{s.image_path}: no master found within the masters' radii "
                                 f"± --band-mm")
            d = 2 * fit_circle(pts).radius_mm
            k = int(np.argmin([abs(d - m) for m in D]))
            if abs(d - D[k]) > 2 * args.band_mm:
                raise UsageError(f"{s.image_path}: reads Ø{d:.3f} mm, none of the masters "
                                 f"{args.master_diameter_mm}")
        res = inverse_triangulate(img, cal, grid_about(D[k] / 2), peak=args.peak)
        if args.bias_model == "twin":
            res = _twin_corrected_raw(res, cal, grid_about(D[k] / 2), args)
        results.append(res)
        shot_d.append(D[k])
        shot_u.append(U[k])
    missing = [d for d in D if d not in shot_d]
    if missing:
        raise UsageError(f"--master-diameter-mm: no reference shot of the Ø{missing[0]:g} mm "
                         f"master among the inputs")
    try:
        fit = master_fit(results, shot_d, u_diameters_mm=shot_u)
    except ValueError as exc:
        raise UsageError(f"compensate: {exc}") from None
    rec = fit.to_dict()
    save_calibration(out, dataclasses.replace(
        cal, view_offsets_mm=fit.offsets_mm, view_radial_offsets_mm=fit.radial_offset_mm,
        view_scales=fit.scale, master=rec))
    views = sorted(fit.radial_offset_mm)
    print(f"mastered with {len(results)} shot(s) of " + " and ".join(
        f"Ø{d:g} mm (u {1e3 * u:.1f} µm)" for d, u in zip(fit.diameters_mm, fit.u_diameters_mm))
        + f", rms {1e3 * fit.rms_mm:.2f} µm ({fit.n_outliers} of "
          f"{fit.n_points + fit.n_outliers} points dropped as outliers) -> {out}")
    for v in views:
        t = fit.offsets_mm.get(v)
        print(f"  {v:8s} " + (f"translation ({1e3 * t[0]:+.1f}, {1e3 * t[1]:+.1f}) µm, "
                              if t is not None else "") +
              f"radial {1e3 * fit.radial_offset_mm[v]:+.2f} µm"
              + (f", scale {fit.scale[v]:.6f}" if fit.fitted_scale else "")
              + f"; u(radius) {1e3 * fit.u_radius_mm[v]:.2f} µm")
    return 0


def cmd_score(args) -> int:

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
    if metrics.get("rejected"):
        n_valid = max(metrics["n_points"] + metrics.get("n_spurious", 0), 1)
        print("  rejected without the truth: " + ", ".join(
            f"{n} {k}" for k, n in metrics["rejected"].items()) + (
            f"; {metrics.get('n_spurious', 0)} spurious still valid (truth-aware, "
            f"{100 * metrics.get('n_spurious', 0) / n_valid:.2f} % of the valid points)"
            if "n_spurious" in metrics else ""))
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


def cmd_calibrate(args) -> int:
    from lts360.experiments.calibration_run import format_report, run_calibrate

    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if not 1 <= args.spp <= MAX_SPP:
        raise UsageError(f"--spp: must be in [1, {MAX_SPP}], got {args.spp}")
    if args.target_spp is not None and not 1 <= args.target_spp <= MAX_SPP:
        raise UsageError(f"--target-spp: must be in [1, {MAX_SPP}], got {args.target_spp}")
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


def cmd_inspect(args) -> int:
    """``lts360 inspect``: every input is checked before anything is written."""
    from lts360.inspect.extremes import FILTER_UPR_RANGE
    from lts360.inspect.nominal import ToleranceBand, load_nominal
    from lts360.inspect.report import write_report
    from lts360.inspect.run import inspect_cloud
    from lts360.recon.triangulation.cloud import read_cloud

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out: {str(out)!r} exists and is not a directory")
    if not out.parent.exists():
        raise UsageError(f"--out: directory {str(out.parent)!r} does not exist")
    if args.tolerance_mm is not None and (args.upper_mm is not None or args.lower_mm is not None):
        raise UsageError("--tolerance-mm: give either it or --upper-mm/--lower-mm, not both")
    if (args.upper_mm is None) != (args.lower_mm is None):
        raise UsageError("--upper-mm/--lower-mm: give both limits")
    if not args.lump_mm > 0:
        raise UsageError(f"--lump-mm: must be > 0, got {args.lump_mm}")
    if not args.lump_arc_mm > 0:
        raise UsageError(f"--lump-arc-mm: must be > 0, got {args.lump_arc_mm}")
    if not (args.u_radial_mm >= 0 and np.isfinite(args.u_radial_mm)):
        raise UsageError(f"--u-radial-mm: must be >= 0, got {args.u_radial_mm}")
    if not 2 <= args.draws <= 10000:
        raise UsageError(f"--draws: must be in [2, 10000], got {args.draws}")
    lo, hi = FILTER_UPR_RANGE
    if args.filter_upr is not None and not (np.isfinite(args.filter_upr)
                                            and lo <= args.filter_upr <= hi):
        raise UsageError(f"--filter-upr: must be in [{lo:g}, {hi:g}], got {args.filter_upr:g}")
    if args.filter == "none" and args.filter_upr is not None:
        raise UsageError("--filter-upr: give it or --filter none, not both")
    from lts360.inspect.tolerances import check_ovality_max, parse_diameter_tolerance

    diameter_tol = None if args.diameter_mm is None else parse_diameter_tolerance(args.diameter_mm)
    ovality_max = None if args.ovality_max_mm is None else check_ovality_max(args.ovality_max_mm)
    band = None
    if args.tolerance_mm is not None:
        band = ToleranceBand.symmetric(args.tolerance_mm)
    elif args.upper_mm is not None:
        band = ToleranceBand(args.upper_mm, args.lower_mm)
    if band is not None and args.nominal is None:
        raise UsageError("--tolerance-mm/--upper-mm/--lower-mm: need --nominal")
    cloud = read_cloud(args.cloud)
    nominal = None if args.nominal is None else load_nominal(args.nominal)
    cal = None
    if args.calibration is not None:
        from lts360.recon.model import load_calibration

        cal = load_calibration(args.calibration)
    truth = None
    if args.truth is not None:
        from lts360.inspect.truth import load_truth

        truth = load_truth(args.truth)
    u_radial = args.u_radial_mm
    u_twin = _twin_u_mm(args.cloud)
    if u_twin is not None:  # the bias correction's own type-B part, beside --u-radial-mm
        u_radial = float(np.hypot(u_radial, u_twin))
    from lts360.recon.triangulation.cloud import read_cloud_master

    mastered = read_cloud_master(args.cloud)
    # the mastering's u (the masters' diameters and the fit): the largest of the views'
    u_master = 1e-3 * max(mastered.values()) if mastered else None
    if u_master is not None:
        u_radial = float(np.hypot(u_radial, u_master))
    t0 = time.perf_counter()
    ins = inspect_cloud(cloud, nominal=nominal, band=band, calibration=cal, truth=truth,
                        lump_threshold_mm=args.lump_mm, n_draws=args.draws, seed=args.seed,
                        u_radial_mm=u_radial, filter_upr=args.filter_upr,
                        use_filter=args.filter != "none", diameter_tol=diameter_tol,
                        ovality_max_mm=ovality_max, lump_arc_mm=args.lump_arc_mm,
                        source=str(args.cloud))
    ins.data["command"] = "lts360 " + " ".join(shlex.quote(a) for a in args.argv) \
        if getattr(args, "argv", None) else None
    ins.data["calibration"] = args.calibration
    if u_master is not None:
        ins.data["settings"]["master_u_radius_mm"] = u_master
        print(f"  the cloud is mastered: its u ({1e3 * u_master:.2f} µm radial, the masters' "
              f"diameters and the fit) is counted in the sizes' U")
    if u_twin is not None:
        ins.data["settings"]["twin_u_inputs_mm"] = u_twin
        print(f"  the cloud is twin-corrected: its inputs' u ({1e3 * u_twin:.2f} µm radial) is "
              f"counted in the sizes' U" + (f" with --u-radial-mm {args.u_radial_mm:g}"
                                            if args.u_radial_mm else ""))
    write_report(ins, out)
    d = ins.data
    tr = d["scan"]["trends"]["d_ls_mm"]
    print(f"{d['n_sections']} section(s) inspected in {time.perf_counter() - t0:.2f} s; mean LS "
          f"diameter {tr['mean']:.4f} mm; calibration u: "
          f"{d['settings']['calibration_uncertainty']}")
    for e in d["scan"]["events"]:
        print(f"  {e['kind']} at z = {e['z_extreme_mm']:.2f} mm ({e['length_mm']:.2f} mm long, "
              f"{1e3 * e['deviation_mm']:+.1f} µm)")
    for e in d["scan"]["local_events"]:
        print(f"  local {e['kind']} at z = {e['z_extreme_mm']:.2f} mm, θ = {e['theta_deg']:.1f}° "
              f"({e['arc_mm']:.1f} mm of arc): {1e3 * e['depth_mm']:+.1f} µm ± "
              f"{1e3 * e['U_k2_mm']:.1f} (k = 2), p_noise {e['p_noise']:.2g}")
    if d["nominal"] and "pass" in d["nominal"]:
        print(f"  against {d['nominal']['source']}: {'PASS' if d['nominal']['pass'] else 'FAIL'}")
    if d["verdict"] is not None:
        v = d["verdict"]
        print("PASS" if v["pass"] else "FAIL: " + "; ".join(v["failed"][:5])
              + (f" and {len(v['failed']) - 5} more" if len(v["failed"]) > 5 else ""))
    if d["sections_skipped"]:
        print(f"lts360: inspect: {len(d['sections_skipped'])} section(s) with too few valid "
              f"points left out", file=sys.stderr)
    print(f"wrote {out}/report.html, inspection.json, sections.csv, figures")
    return 1 if d["verdict"] is not None and not d["verdict"]["pass"] else 0
