"""The studies (``lts360 study ...``) and the demo."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lts360.cli.usage import UsageError, _set_variant
from lts360.simulator.render import MAX_SPP


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


def _check_placement(placement_mm: float) -> None:
    if not 0 <= placement_mm <= 10:
        raise UsageError(f"--placement-mm: must be in [0, 10], got {placement_mm}")


def cmd_study_plug_gauge(args) -> int:
    from lts360.experiments.gauge_study import format_gauge_table, run_plug_gauge_study

    common = _study_common(args)
    if not 1 <= args.trials <= 10000:
        raise UsageError(f"--trials: must be in [1, 10000], got {args.trials}")
    _check_shots(args.compensation_shots)
    _check_placement(args.placement_mm)
    _optional_file(args.calibration, "--calibration")
    _study_rig(args.rig)
    _set_variant(args.variant)
    table = run_plug_gauge_study(args.out, trials=args.trials, calibration=args.calibration,
                                 noise=args.noise, spp=args.spp, rig=args.rig,
                                 compensation_shots=args.compensation_shots,
                                 placement_mm=args.placement_mm, master=args.master,
                                 bias_model=args.bias_model, compensate=args.compensate,
                                 steps=args.steps, workers=args.workers or 1,
                                 max_scatter=_gauge_max_scatter(args.max_scatter), **common)
    print(format_gauge_table(table))
    print(f"wrote {args.out}/ (table.txt, table.json, plug-gauge.png, trials/results.nc)")
    return 0


def cmd_study_monte_carlo(args) -> int:
    from lts360.experiments.gauge_study import ensure_calibration
    from lts360.experiments.monte_carlo import (
        PLACEMENT_SPP,
        format_mc,
        run_monte_carlo_study,
    )

    common = _study_common(args)
    if not 2 <= args.trials <= 10**6:
        raise UsageError(f"--trials: must be in [2, 1000000], got {args.trials}")
    if not 2 <= args.batch <= 10**5 or not 2 <= args.sensitivity_trials <= 10**5:
        raise UsageError("--batch and --sensitivity-trials must be >= 2")
    if not 1 <= args.placements <= 100:
        raise UsageError(f"--placements: must be in [1, 100], got {args.placements}")
    if args.spp is not None and not 1 <= args.spp <= MAX_SPP:
        raise UsageError(f"--spp: must be in [1, {MAX_SPP}], got {args.spp}")
    if not 1 <= args.digits <= 4:
        raise UsageError(f"--digits: must be in [1, 4], got {args.digits}")
    _check_shots(args.compensation_shots)
    _check_placement(args.placement_mm)
    if args.master and args.no_compensate:
        raise UsageError("--master: the mastering is a compensation; drop --no-compensate")
    if args.twin_per != "trial" and args.bias_model != "twin":
        raise UsageError("--twin-per: there is no twin with --bias-model none")
    master = args.master is not False and not args.no_compensate
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
                                    master=master, bias_model=args.bias_model,
                                    twin_per=args.twin_per,
                                    steps=args.steps, adaptive=args.adaptive,
                                    batch=args.batch, n_dig=args.digits,
                                    sensitivity_trials=args.sensitivity_trials,
                                    placements=args.placements, placement_mm=args.placement_mm,
                                    spp=PLACEMENT_SPP if args.spp is None else args.spp,
                                    workers=args.workers, **common)
    print(format_mc(summary))
    print(f"wrote {out}/ (summary.json, monte-carlo.png, mc/batch_*/results.nc)")
    return 0


def _gauge_max_scatter(value) -> int:
    """``--max-scatter`` of the plug-gauge study: ``auto`` by the gauge's material."""
    from lts360.scenes.materials import resolve_max_scatter
    from lts360.scenes.objects import build_object

    return resolve_max_scatter(value, build_object("plug-gauge").material)


def cmd_study_examples(args) -> int:
    from lts360.experiments.examples_study import (
        EXTRA_EXAMPLES,
        PAPER_EXAMPLES,
        format_examples,
        run_examples_study,
    )

    common = _study_common(args)
    objects = _objects_arg(args.objects, list(PAPER_EXAMPLES) + list(EXTRA_EXAMPLES),
                           PAPER_EXAMPLES)
    if not 0 < args.section_scale <= 1:
        raise UsageError(f"--section-scale: must be in (0, 1], got {args.section_scale}")
    _optional_file(args.calibration, "--calibration")
    _set_variant(args.variant)
    table = run_examples_study(args.out, objects=objects, noise=args.noise, spp=args.spp,
                               calibration=args.calibration, section_scale=args.section_scale,
                               workers=args.workers or 1, max_scatter=args.max_scatter,
                               frames_dir=args.frames, **common)
    print(format_examples(table))
    print(f"wrote {args.out}/ (table.txt, clouds/*.ply, figures/*.png, trials/results.nc)")
    return 0


def cmd_study_algorithms(args) -> int:
    from lts360.experiments.algorithms import (
        DEFAULT_OBJECTS,
        format_algorithms,
        run_algorithms_study,
    )
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


def cmd_study_design_space(args) -> int:
    from lts360.experiments.design_space import (
        format_design_space,
        parse_range,
        run_design_space_study,
    )

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


def cmd_demo(args) -> int:
    from lts360.experiments.demo import run_demo

    if not args.radius_mm > 0:
        raise UsageError(f"--radius-mm: must be > 0, got {args.radius_mm}")
    render = not args.no_render
    if render:
        _set_variant(args.variant)
    if not 1 <= args.gauge_trials <= 1000:
        raise UsageError(f"--gauge-trials: must be in [1, 1000], got {args.gauge_trials}")
    run_demo(Path(args.out), radius_mm=args.radius_mm, render=render, paper=not args.quick,
             gauge_trials=args.gauge_trials, seed=args.seed,
             gauge_options={"compensate": args.compensate, "master": args.master,
                            "bias_model": args.bias_model, "steps": args.steps})
    return 0


def _floats(text: str, option: str, *, positive: bool = False, nonneg: bool = False) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"{option}: expected comma-separated numbers, got {text!r}")
    if not vals:
        raise UsageError(f"{option}: no value given")
    if positive and min(vals) <= 0:
        raise UsageError(f"{option}: every value must be > 0, got {text!r}")
    if nonneg and min(vals) < 0:
        raise UsageError(f"{option}: every value must be >= 0, got {text!r}")
    return vals


def cmd_study_line_speed(args) -> int:
    from lts360.experiments.line_speed import (
        DEFAULT_OBJECTS,
        format_line_speed,
        run_line_speed_study,
    )
    from lts360.scenes.objects import object_types

    common = _study_common(args)
    objects = args.objects.split(",") if args.objects else list(DEFAULT_OBJECTS)
    known = set(object_types())
    for name in objects:
        if name.split(":")[0] not in known:
            raise UsageError(f"--objects: unknown object {name!r}")
    speeds = _floats(args.speeds_mm_s, "--speeds-mm-s")
    exposures = ([0.0] if args.exposures_us.strip() == "auto"
                 else _floats(args.exposures_us, "--exposures-us", positive=True))
    shutters = args.shutters.split(",")
    if not shutters or any(s not in ("global", "rolling") for s in shutters):
        raise UsageError(f"--shutters: global, rolling or both, got {args.shutters!r}")
    if "rolling" in shutters and not args.line_time_us > 0:
        raise UsageError(f"--line-time-us: must be > 0 for a rolling shutter, got {args.line_time_us}")
    if not args.profile_rate_hz > 0:
        raise UsageError(f"--profile-rate-hz: must be > 0, got {args.profile_rate_hz}")
    if not args.accuracy_um > 0:
        raise UsageError(f"--accuracy-um: must be > 0, got {args.accuracy_um}")
    if not 0 < args.scale <= 1:
        raise UsageError(f"--scale: must be in (0, 1], got {args.scale}")
    if not 1 <= args.spp <= MAX_SPP:
        raise UsageError(f"--spp: must be in [1, {MAX_SPP}], got {args.spp}")
    _study_rig(args.rig)
    _set_variant(args.variant)
    try:
        table = run_line_speed_study(args.out, objects=objects, speeds_mm_s=speeds,
                                     exposures_us=exposures, shutters=shutters,
                                     line_time_us=args.line_time_us, scale=args.scale,
                                     spp=args.spp, noise=args.noise, rig=args.rig,
                                     accuracy_um=args.accuracy_um,
                                     profile_rate_hz=args.profile_rate_hz,
                                     workers=args.workers or 1, **common)
    except ValueError as exc:  # e.g. a feed that leaves the object's measured zone
        raise UsageError(f"line-speed: {exc}")
    print(format_line_speed(table))
    print(f"wrote {args.out}/ (table.txt, table.json, line-speed.png, trials/results.nc)")
    return 0


def cmd_study_bias(args) -> int:
    from lts360.experiments.bias_study import format_bias_table, run_bias_study

    common = _study_common(args)
    diameters = _floats(args.diameters_mm, "--diameters-mm", positive=True)
    placements = []
    for item in args.placements_mm.split(","):
        try:
            x, y = (float(v) for v in item.split(":"))
        except ValueError:
            raise UsageError(f"--placements-mm: x:y pairs separated by commas, got {item!r}") \
                from None
        if not (np.isfinite(x) and np.isfinite(y) and np.hypot(x, y) <= 20):
            raise UsageError(f"--placements-mm: offsets within 20 mm of the axis, got {item!r}")
        placements.append((x, y))
    if any(not 1 <= d <= 60 for d in diameters):
        raise UsageError(f"--diameters-mm: each in [1, 60] mm, got {args.diameters_mm!r}")
    for name in ("spp", "twin_spp"):
        if not 1 <= getattr(args, name) <= MAX_SPP:
            raise UsageError(f"--{name.replace('_', '-')}: must be in [1, {MAX_SPP}], got "
                             f"{getattr(args, name)}")
    _study_rig(args.rig)
    _set_variant(args.variant)
    table = run_bias_study(args.out, diameters_mm=diameters, placements_mm=placements,
                           spp=args.spp, twin_spp=args.twin_spp, noise=args.noise, rig=args.rig,
                           workers=args.workers or 1, variant=args.variant, **common)
    print(format_bias_table(table))
    print(f"wrote {args.out}/ (table.txt, table.json, trials/results.nc)")
    return 0


def cmd_study_interreflection(args) -> int:
    """``lts360 study interreflection``: the interreflected light against Mitsuba's ``path``
    (``validation.json``) and the secondary-stripe figures (``<object>.png``,
    ``figures.json``)."""
    import json

    from lts360.experiments.interreflection import secondary_stripe_figure, validate_against_path
    from lts360.scenes.objects import object_types

    names = [n.strip() for n in args.figures.split(",") if n.strip()]
    unknown = [n for n in names if n not in object_types()]
    if unknown:
        raise UsageError(f"--figures: unknown object {unknown[0]!r}; choose from "
                         f"{', '.join(object_types())}")
    if args.figure_spp < 1 or args.figure_spp > MAX_SPP:
        raise UsageError(f"--figure-spp: must be in [1, {MAX_SPP}], got {args.figure_spp}")
    _set_variant(args.variant)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not args.skip_validation:
        val = validate_against_path()
        (out / "validation.json").write_text(json.dumps(val, indent=2))
        for name, c in val.items():
            print(f"{name}: ours {c['total_a']:.3f} ± {c['se_total_a']:.3f}, path "
                  f"{c['total_b']:.3f} ± {c['se_total_b']:.3f} "
                  f"({100 * c['rel_diff_total']:+.2f} %), chi2/dof {c['chi2_per_dof']:.3f} over "
                  f"{c['n_pixels']} px, |z| > 4: {100 * c['frac_abs_z_over_4']:.2f} %", flush=True)
    figs = {}
    for name in names:
        figs[name] = secondary_stripe_figure(name, out / f"{name}.png", spp=args.figure_spp)
        print(f"{name}: laser light +{100 * figs[name]['gain']:.1f} %, secondary peak "
              f"{figs[name]['secondary_peak_over_primary_peak']:.3g} of the primary", flush=True)
    (out / "figures.json").write_text(json.dumps(figs, indent=2))
    return 0
