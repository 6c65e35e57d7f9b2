"""``lts360 design optimize|map|check``: rig design on the differentiable model (lts360.design)
and the model's check against rendered simulation (lts360.experiments.design_check)."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from lts360.cli.usage import UsageError


def _floats(text: str, what: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise UsageError(f"{what}: expected comma-separated numbers, got {text!r}") from None
    if not vals:
        raise UsageError(f"{what}: expected at least one number")
    return vals


def _bounds(items) -> dict:
    out = {}
    for item in items or []:
        name, sep, rng = item.partition("=")
        lo, sep2, hi = rng.partition(":")
        if not sep or not sep2:
            raise UsageError(f"--bound: expected NAME=LO:HI, got {item!r}")
        try:
            out[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise UsageError(f"--bound {item!r}: LO and HI must be numbers") from None
    return out


def _space_and_conditions(args):
    from lts360.design.model import Conditions
    from lts360.design.params import DesignSpace

    free = None if args.free is None else [f.strip() for f in args.free.split(",") if f.strip()]
    space = DesignSpace.create(args.rig, free=free, bounds=_bounds(args.bound))
    cond = Conditions(diameters_mm=_floats(args.diameters_mm, "--diameters-mm"),
                      placement_mm=args.placement_mm, min_coverage_deg=args.min_coverage_deg,
                      min_overlap_deg=args.min_overlap_deg, margin_px=args.image_margin_px,
                      speckle=args.speckle, n_theta=args.n_theta,
                      compensate=not args.no_compensation,
                      compensation_diameter_mm=args.compensation_diameter_mm,
                      compensation_shots=args.compensation_shots,
                      master=bool(args.master), bias_model=args.bias_model,
                      calibration=_calibration(args.calibration, space.base))
    return space, cond


def _calibration(source, base):
    """``--calibration``: none, ``plan`` (the covariance predicted for ``lts360 calibrate``'s
    plan of the base rig), or a calibration JSON whose covariance the model propagates."""
    from lts360.design.shares import CalibrationCovariance

    if source is None or source == "none":
        return None
    if source == "plan":
        from lts360.design.calib_covariance import CalibrationPlan

        try:
            return CalibrationPlan.from_rig(base)
        except ValueError as exc:
            raise UsageError(f"--calibration plan: {exc}") from None
    path = Path(source)
    if not path.is_file():
        raise UsageError(f"--calibration: no file {source!r} (a calibration JSON written by "
                         "lts360 calibrate, 'plan' or 'none')")
    try:
        return CalibrationCovariance.from_file(path)
    except json.JSONDecodeError as exc:
        raise UsageError(f"--calibration {source}: not a calibration JSON ({exc})") from None
    except ValueError as exc:
        raise UsageError(f"--calibration {source}: {exc}") from None


def _write_dir(out: Path, files: dict[str, str | bytes]) -> None:
    """Write ``files`` into a new folder and put it at ``out`` in one rename (replacing it)."""
    out = Path(out)
    parent = out.resolve().parent
    if not parent.is_dir():
        raise UsageError(f"--out: directory {str(parent)!r} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    try:
        for name, data in files.items():
            (tmp / name).write_bytes(data if isinstance(data, bytes) else data.encode())
        old = None
        if out.exists():
            old = parent / f".{out.name}.old-{os.getpid()}"
            out.rename(old)
        tmp.rename(out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def cmd_design_optimize(args) -> int:
    from lts360.design.optimize import optimize, report_dict, report_text

    if args.starts < 1:
        raise UsageError(f"--starts: must be >= 1, got {args.starts}")
    if not 2 <= args.grid_per_axis <= 10:
        raise UsageError(f"--grid-per-axis: must be in [2, 10], got {args.grid_per_axis}")
    if args.grid_points < args.starts:
        raise UsageError("--grid-points: must be >= --starts")
    space, cond = _space_and_conditions(args)
    t0 = time.perf_counter()
    res = optimize(space, cond, starts=args.starts, points_per_axis=args.grid_per_axis,
                   max_grid_points=args.grid_points, seed=args.seed, progress=print)
    text = report_text(res)
    rep = report_dict(res)
    rep["seconds"] = time.perf_counter() - t0
    toml = space.toml(res.optimum.x, name=f"{space.base.name}-optimized")
    _write_dir(Path(args.out), {"rig.toml": toml, "report.json": json.dumps(rep, indent=2),
                                "report.txt": text + "\n"})
    print(text)
    print(f"wrote {args.out}/rig.toml, report.json, report.txt "
          f"({rep['seconds']:.1f} s)")
    return 0


def cmd_design_map(args) -> int:
    from lts360.design.maps import QUANTITIES, design_map, plot_map

    if args.quantity not in QUANTITIES:
        raise UsageError(f"--quantity: one of {', '.join(QUANTITIES)}, got {args.quantity!r}")
    if not 2 <= args.n <= 400:
        raise UsageError(f"--n: must be in [2, 400], got {args.n}")
    if args.x == args.y:
        raise UsageError("--x and --y must be different parameters")
    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise UsageError(f"--out: must be a .png file, got {args.out!r}")
    if not out.resolve().parent.is_dir():
        raise UsageError(f"--out: directory {str(out.resolve().parent)!r} does not exist")
    args.free = f"{args.x},{args.y}"
    space, cond = _space_and_conditions(args)
    t0 = time.perf_counter()
    m = design_map(space, args.x, args.y, cond, n=args.n)
    base = space.base_x()
    tmp = out.with_name(f".{out.name}.tmp.png")
    try:
        plot_map(m, args.quantity, tmp, base_xy=(base[0], base[1]),
                 min_coverage_deg=cond.min_coverage_deg)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    print(f"{args.n}×{args.n} designs of the model in {time.perf_counter() - t0:.1f} s; "
          f"wrote {out}")
    return 0


def add_design_parser(sub) -> None:
    from lts360.design.params import PARAMETERS

    s = sub.add_parser("design", help="rig design on the differentiable model: optimize, map, "
                       "check")
    ds = s.add_subparsers(dest="design_command", metavar="ACTION", parser_class=type(s))
    ds.required = True
    names = ", ".join(p.name for p in PARAMETERS)

    def common(q):
        q.add_argument("--rig", default="paper", help="base rig: preset or TOML (fixes every "
                       "parameter that is not free)")
        q.add_argument("--bound", action="append", metavar="NAME=LO:HI",
                       help="search bounds of a free parameter (repeatable)")
        q.add_argument("--diameters-mm", default="10,20,30", help="section diameters; the "
                       "objective is the worst (default 10,20,30)")
        q.add_argument("--placement-mm", type=float, default=0.0, help="also the centre "
                       "offset by this much in ±x, ±y")
        q.add_argument("--min-coverage-deg", type=float, default=359.0)
        q.add_argument("--min-overlap-deg", type=float, default=5.0,
                       help="direct/mirror and mirror/mirror overlap")
        q.add_argument("--image-margin-px", type=float, default=20.0)
        q.add_argument("--speckle", default="pixel", choices=("pixel", "dorsch"))
        q.add_argument("--n-theta", type=int, default=180, help="θ samples of the model")
        q.add_argument("--no-compensation", action="store_true", help="the measurement "
                       "without the §4.4 compensation (default: with it; its own noise counts)")
        q.add_argument("--compensation-diameter-mm", type=float, default=19.9987,
                       help="the compensation's reference, centred (default the plug gauge)")
        q.add_argument("--compensation-shots", type=int, default=1,
                       help="reference images the compensation is fitted to")
        q.add_argument("--master", action="store_true", help="the compensation's reference is "
                       "a master of known diameter (lts360 compensate --master-diameter-mm): "
                       "it removes each view's line-centre bias at that diameter")
        q.add_argument("--bias-model", choices=("twin", "none"), default="twin",
                       help="twin (default): the measurement removes the line-centre bias with "
                       "its twin, which leaves a tenth of it; none: the whole bias is a share "
                       "of U")
        q.add_argument("--calibration", default=None, metavar="plan|FILE|none",
                       help="add the calibration's share: 'plan' (the covariance predicted "
                       "for every design from lts360 calibrate's board plan of the base rig; "
                       "the first evaluation records the model, ~1 min) or a calibration "
                       "file's (lts360 calibrate's calibration.json); default none")

    q = ds.add_parser("optimize", help="multi-start L-BFGS-B on the model, seeded by a grid "
                      "of it; writes rig.toml and a report")
    q.add_argument("--out", required=True, help="output directory (replaced atomically)")
    q.add_argument("--free", default=None, help=f"comma-separated free parameters (default "
                   f"all: {names})")
    q.add_argument("--starts", type=int, default=6)
    q.add_argument("--grid-per-axis", type=int, default=3)
    q.add_argument("--grid-points", type=int, default=1024,
                   help="most grid designs (a seeded subset of the full grid)")
    q.add_argument("--seed", type=int, default=0)
    common(q)
    q.set_defaults(func=cmd_design_optimize)

    q = ds.add_parser("map", help="a two-parameter map of the model (PNG)")
    q.add_argument("--x", required=True, help=f"parameter on x ({names})")
    q.add_argument("--y", required=True, help="parameter on y")
    q.add_argument("--n", type=int, default=100, help="grid points per axis")
    q.add_argument("--quantity", default="U_um", help="U_um, sigma_R_noise_um, "
                   "sigma_R_comp_um, sigma_R_cal_um, point_rms_um, coverage_deg, objective")
    q.add_argument("--out", default="design-map.png")
    common(q)
    q.set_defaults(func=cmd_design_map)

    q = ds.add_parser("check", help="the model against rendered simulation: radius σ and "
                      "per-point σ (renders; minutes)")
    q.add_argument("rigs", nargs="+", help="presets or rig TOML files")
    q.add_argument("--draws", type=int, default=200, help="noisy images per rig (default 200)")
    q.add_argument("--spp", type=int, default=None,
                   help="samples per pixel of the renders (default 16; 64 with --pipeline, "
                        "where 16 spp of sampling noise at f/1.4 is as large as the image's "
                        "own)")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--json", default=None, metavar="FILE", help="write the results as JSON")
    q.add_argument("--shares", action="store_true",
                   help="simulate the radius σ share by share (noise, compensation, "
                        "calibration) for the gauge moved off the axis")
    q.add_argument("--placement-mm", type=float, default=None,
                   help="with --shares or --calibrations: offset of the gauge along +x, "
                        "0..10 mm (default 2)")
    q.add_argument("--calibration", default=None, metavar="FILE",
                   help="with --shares: a calibration file whose uncertainty is drawn")
    q.add_argument("--calibrations", nargs="+", default=None, metavar="FILE",
                   help="the calibration share from these calibrations of the (one) rig: "
                        "each compensates and measures the gauge (render → calibrate → "
                        "compensate → measure)")
    q.add_argument("--pipeline", action="store_true",
                   help="the section's radius U(k=2) through the whole user pipeline, model "
                        "beside it: per rig and seed, lts360 calibrate on rendered boards, "
                        "compensation with the gauge as master, noisy placements measured "
                        "with the twin (the plug-gauge study; needs --out)")
    q.add_argument("--seeds", default="0,1,2",
                   help="with --pipeline: calibration seeds (default 0,1,2)")
    q.add_argument("--placements", type=int, default=5,
                   help="with --pipeline: placements per seed (default 5)")
    q.add_argument("--out", default=None,
                   help="with --pipeline: output folder (OUT/<rig>/seed<S>/ is reused when done)")
    q.add_argument("--no-master-check", action="store_true",
                   help="with --pipeline: do not measure a noise-free centred image with each "
                        "seed's mastered calibration (what the master left, per seed)")
    q.set_defaults(func=cmd_design_check)


def _write_json(path, data) -> None:
    """Write ``data`` to ``path`` through a temporary name (never a half-written file)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w") as fh:
        json.dump(data, fh, indent=2)
    os.replace(tmp, path)


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def cmd_design_check(args) -> int:
    """``lts360 design check``: the design model against full simulation (renders)."""
    from lts360.cli.usage import _set_variant

    if args.pipeline:
        return _check_pipeline(args)
    if args.out is not None or args.no_master_check:
        raise UsageError("--out and --no-master-check need --pipeline")
    args.spp = 16 if args.spp is None else args.spp
    if args.calibrations is not None:
        return _check_calibrations(args)
    if not args.shares:
        if args.placement_mm is not None or args.calibration is not None:
            raise UsageError("--placement-mm and --calibration need --shares")
        return _check_rigs(args)
    return _check_shares(args, _set_variant)


def _check_pipeline(args) -> int:
    from lts360.cli.usage import _set_variant
    from lts360.experiments.design_pipeline import check_pipeline, format_pipeline

    if args.out is None:
        raise UsageError("--pipeline needs --out")
    if args.shares or args.calibrations is not None or args.calibration is not None:
        raise UsageError("--pipeline: not with --shares, --calibration or --calibrations")
    try:
        seeds = [int(v) for v in args.seeds.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"--seeds: comma-separated integers, got {args.seeds!r}") from None
    _load_rigs(args.rigs)  # one line for a bad rig
    _set_variant(None)
    try:
        res = check_pipeline(args.rigs, args.out, seeds=seeds, placements=args.placements,
                             placement_mm=0.3 if args.placement_mm is None
                             else args.placement_mm, spp=64 if args.spp is None else args.spp,
                             masters=not args.no_master_check)
    except ValueError as exc:
        raise UsageError(_first_line(exc)) from None
    print("\n".join(format_pipeline(res)))
    if args.json:
        _write_json(args.json, res)
    return 0


def _load_rigs(sources):
    from lts360.scenes.rig_io import load_rig

    try:
        return [(src, load_rig(src)) for src in sources]
    except (ValueError, OSError) as exc:
        raise UsageError(_first_line(exc)) from None


def _check_rigs(args) -> int:
    from lts360.cli.usage import _set_variant
    from lts360.experiments.design_check import check_rig

    rigs = _load_rigs(args.rigs)
    _set_variant(None)
    rows = []
    for src, rig in rigs:
        r = check_rig(rig, draws=args.draws, spp=args.spp, seed=args.seed)
        r["source"] = src
        rows.append(r)
        m, s = r["model_pixel"], r["simulation"]
        print(f"{src}: σ_R model {m['sigma_R_um']:.2f} µm (dorsch "
              f"{r['model_dorsch']['sigma_R_um']:.2f}), simulated {s['sigma_R_um']:.2f} "
              f"[{s['sigma_R_95_um'][0]:.2f}, {s['sigma_R_95_um'][1]:.2f}] µm ({s['draws']} draws); "
              f"per point model {m['point_rms_um']:.1f} µm (dorsch "
              f"{r['model_dorsch']['point_rms_um']:.1f}), simulated {s['point_rms_um']:.1f} µm; "
              f"coverage model {m['coverage_deg']:.1f}°, measured {s['coverage_deg']:.1f}° "
              f"({s['seconds']:.0f} s)", flush=True)
    if args.json:
        _write_json(args.json, rows)
    return 0


def _check_shares(args, set_variant) -> int:
    from lts360.experiments.design_check import (
        check_shares,
        file_uncertainty,
        format_shares,
        share_args_error,
    )

    placement = 2.0 if args.placement_mm is None else args.placement_mm
    msg = share_args_error(args.draws, args.spp, placement, args.calibration)
    if msg is not None:
        raise UsageError(msg)
    rigs = _load_rigs(args.rigs)
    if args.calibration is not None:
        try:
            file_uncertainty(args.calibration)
        except (ValueError, OSError) as exc:
            raise UsageError(_first_line(exc)) from None
    set_variant(None)
    rows = []
    for src, rig in rigs:
        r = check_shares(rig, draws=args.draws, spp=args.spp, seed=args.seed,
                         placement_mm=placement, calibration=args.calibration, progress=True)
        r["source"] = src
        rows.append(r)
        print("\n".join(format_shares(r)), flush=True)
    if args.json:
        _write_json(args.json, rows)
    return 0


def _check_calibrations(args) -> int:
    from lts360.cli.usage import _set_variant
    from lts360.experiments.design_check import MAX_PLACEMENT_MM, check_calibrations

    placement = 2.0 if args.placement_mm is None else args.placement_mm
    if len(args.rigs) != 1:
        raise UsageError("--calibrations: give exactly one rig")
    if len(args.calibrations) < 3:
        raise UsageError(f"--calibrations: need at least 3 files, got {len(args.calibrations)}")
    if not 0 <= placement <= MAX_PLACEMENT_MM:
        raise UsageError(f"--placement-mm: must be in [0, {MAX_PLACEMENT_MM:g}], "
                         f"got {placement:g}")
    missing = [f for f in args.calibrations if not os.path.isfile(f)]
    if missing:
        raise UsageError(f"--calibrations: no file {missing[0]!r}")
    (_, rig), = _load_rigs(args.rigs)
    _set_variant(None)
    r = check_calibrations(rig, args.calibrations, spp=args.spp, seed=args.seed,
                           placement_mm=placement)
    c = r["compensated"]
    for row in r["calibrations"]:
        print(f"  {row['file']}: radius error {row['error_um']:+.2f} µm compensated "
              f"({row['error_uncompensated_um']:+.2f} µm not); model share with its own "
              f"covariance {row['model_file_covariance_um']:.2f} µm")
    print(f"{rig.name} @ +{placement:g} mm: σ over {len(r['calibrations'])} calibrations "
          f"{c['sigma_um']:.2f} [{c['sigma_95_um'][0]:.2f}, {c['sigma_95_um'][1]:.2f}] µm "
          f"(not compensated {r['uncompensated']['sigma_um']:.2f} µm); model: plan "
          f"{r['model_plan_um']:.2f} µm, the files' own covariances {r['model_files_rms_um']:.2f} "
          f"µm (rms)", flush=True)
    if args.json:
        _write_json(args.json, r)
    return 0
