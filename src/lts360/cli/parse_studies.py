"""The parsers of ``lts360 study ...`` and ``lts360 demo`` (their handlers in
``lts360.cli.studies``)."""

from __future__ import annotations

from lts360.cli.studies import (
    cmd_demo,
    cmd_study_algorithms,
    cmd_study_bias,
    cmd_study_design_space,
    cmd_study_examples,
    cmd_study_interreflection,
    cmd_study_line_speed,
    cmd_study_monte_carlo,
    cmd_study_plug_gauge,
)
from lts360.cli.usage import VARIANT_HELP, _Parser
from lts360.simulator.integrator import MAX_SCATTER
from lts360.twin.debias import DEFAULT_TWIN_SPP


def add_study_parsers(sub) -> None:
    """``study`` and its studies, in the order ``--help`` lists them."""
    s = sub.add_parser("study", help="the studies: plug-gauge, examples, design-space, "
                       "monte-carlo, algorithms")
    studies = s.add_subparsers(dest="study", metavar="STUDY", parser_class=_Parser)
    studies.required = True
    _add_plug_gauge(studies)
    _add_monte_carlo(studies)
    _add_examples(studies)
    _add_line_speed(studies)
    _add_interreflection(studies)
    _add_bias(studies)
    _add_design_space(studies)
    _add_algorithms(studies)


def _study_parser(studies, name, help_text):
    """A study's parser with the options every study shares."""
    q = studies.add_parser(name, help=help_text)
    q.add_argument("--out", required=True, help="output directory (results, figures, README)")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--workers", type=int, default=None, help="local processes")
    q.add_argument("--dask", default=None, metavar="ADDRESS",
                   help="run the trials on a Dask distributed scheduler")
    q.add_argument("--variant", default=None, help=VARIANT_HELP)
    return q


def _add_plug_gauge(studies) -> None:
    """``study plug-gauge``."""
    q = _study_parser(studies, "plug-gauge",
                      "paper §4.5: the gauge placed N times, measured with an "
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
    q.add_argument("--placement-mm", type=float, default=0.3, metavar="R",
                   help="placements drawn uniformly in a disc of radius R mm about the axis "
                   "(default 0.3); results are also reported against the distance from it")
    _add_user_steps(q)
    q.add_argument("--max-scatter", choices=("auto",) + tuple(str(k) for k in range(MAX_SCATTER + 1)),
                   default="auto",
                   help="interreflections of the laser light in the gauge's images: 0-3, or "
                        "auto (default): 0 for the ground-steel gauge (not shiny)")
    q.set_defaults(func=cmd_study_plug_gauge)


def _add_user_steps(q) -> None:
    """The steps a user measures with (plug-gauge study and demo), each switchable."""

    q.add_argument("--no-compensate", dest="compensate", action="store_false",
                   help="no §4.4 compensation (and so no master)")
    _add_master_twin_steps(q, master_default=True, what="placement",
                           steps="each step on and off")


def _add_master_twin_steps(q, *, master_default, what: str, steps: str) -> None:
    """The master, the twin and the table of steps, as the plug-gauge study, the demo and the
    Monte Carlo take them (``what``: what each trial measures; ``steps``: what the table
    adds)."""
    import argparse

    q.add_argument("--master", action=argparse.BooleanOptionalAction, default=master_default,
                   help="master the compensation with the gauge's known diameter (default on; "
                   "--no-master: §4.4 alone, the paper's method)")
    q.add_argument("--bias-model", choices=("none", "twin"), default="twin",
                   help=f"twin (default): each {what}'s section (and the master's shots) "
                   "corrected by its twin; none: no line-centre bias correction")
    q.add_argument("--no-steps", dest="steps", action="store_false",
                   help=f"measure each {what} only as configured (default: also with {steps}, "
                   "for the table of steps)")


def _add_monte_carlo(studies) -> None:
    """``study monte-carlo``."""

    q = _study_parser(studies, "monte-carlo",
                      "GUM Supplement 1 Monte Carlo of the gauge radius, GUM "
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
    q.add_argument("--spp", type=int, default=None,
                   help="samples per pixel of the placements' renders (default 256, the study's "
                   "PLACEMENT_SPP: their render noise is common to every trial, a bias of the "
                   "study)")
    q.add_argument("--no-compensate", action="store_true",
                   help="no §4.4 compensation (and so no master)")
    _add_master_twin_steps(q, master_default=None, what="draw",
                           steps="§4.4 alone and §4.4 + master")
    q.add_argument("--compensation-shots", type=int, default=1, metavar="K",
                   help="images of the reference placement each §4.4 compensation is fitted "
                   "to (default 1, as the paper)")
    q.add_argument("--twin-per", choices=("trial", "placement"), default="trial",
                   help="trial (default): each draw's twin rendered from its own section and "
                   "calibration, as a user's measurement; placement: each placement's twin "
                   "correction computed once (noise-free, nominal calibration) and reused — "
                   "about 4x faster a trial, without the correction's own variation with the "
                   "draw (BENCHMARKS.md)")
    q.add_argument("--placement-mm", type=float, default=0.3, metavar="R",
                   help="rendered placements drawn uniformly in a disc of radius R mm about the "
                   "axis (default 0.3); results are also reported against the distance from it")
    q.add_argument("--rig", default="paper", help="rig to render: 'paper' or a TOML file (the "
                   "one the calibration is of)")
    q.set_defaults(func=cmd_study_monte_carlo)


def _add_examples(studies) -> None:
    """``study examples``."""
    q = _study_parser(studies, "examples",
                      "paper §4.6: the eight objects scanned with the paper's "
                      "sections and pitch, clouds, figures, error table")
    q.add_argument("--objects", default=None, help="comma-separated subset (default: all eight)")
    q.add_argument("--noise", choices=("none", "realistic"), default="realistic")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--calibration", default=None, help="measure with this calibration "
                   "(default: the frames' true one)")
    q.add_argument("--section-scale", type=float, default=1.0,
                   help="fraction of the paper's sections to scan (quick looks)")
    q.add_argument("--max-scatter", choices=("auto",) + tuple(str(k) for k in range(MAX_SCATTER + 1)),
                   default="auto",
                   help="interreflections of the laser light: 0-3, or auto (default): 1 for the "
                        "shiny objects (alu-pipe, cut-tube, polished-shaft), 0 for the others")
    q.add_argument("--frames", default=None, help="keep each scan's frames in this folder and "
                   "measure the stored ones when the same scan is asked for again (a changed "
                   "measurement re-run without rendering)")
    q.set_defaults(func=cmd_study_examples)


def _add_line_speed(studies) -> None:
    """``study line-speed``."""
    q = _study_parser(studies, "line-speed",
                      "a moving object: speed × exposure × shutter (global, "
                      "rolling); errors per view as one instant and row-aware, lumps missed")
    q.add_argument("--objects", default=None, help="comma-separated (default cable-8,grooved-shaft)")
    q.add_argument("--speeds-mm-s", default="0,100,300,1000", help="comma-separated feeds")
    q.add_argument("--exposures-us", default="auto", help="comma-separated exposures, or auto "
                   "(what auto-exposure sets for each still object)")
    q.add_argument("--shutters", default="global,rolling", help="global, rolling or both")
    q.add_argument("--line-time-us", type=float, default=10.0, help="rolling shutter line time")
    q.add_argument("--profile-rate-hz", type=float, default=200.0,
                   help="section rate for the lumps-missed table")
    q.add_argument("--accuracy-um", type=float, default=20.0,
                   help="what the motion may add (in quadrature) to the robust RMS error of "
                        "the same sub-frames with the object held still")
    q.add_argument("--noise", choices=("none", "realistic"), default="none")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--scale", type=float, default=0.5, help="image scale (default 0.5)")
    q.add_argument("--rig", default="paper")
    q.set_defaults(func=cmd_study_line_speed)


def _add_interreflection(studies) -> None:
    """``study interreflection``."""
    q = studies.add_parser("interreflection", help="interreflected laser light against "
                           "Mitsuba's path integrator (corner, shiny cylinder) and figures of "
                           "the secondary stripes")
    q.add_argument("--out", required=True, help="output directory")
    q.add_argument("--figures", default="polished-shaft,alu-pipe,cut-tube",
                   help="comma-separated objects to draw (default polished-shaft,alu-pipe,"
                        "cut-tube)")
    q.add_argument("--figure-spp", type=int, default=64)
    q.add_argument("--skip-validation", action="store_true",
                   help="only the figures (the path comparison takes minutes)")
    q.add_argument("--variant", default=None, help=VARIANT_HELP)
    q.set_defaults(func=cmd_study_interreflection)


def _add_bias(studies) -> None:
    """``study bias``."""
    q = _study_parser(studies, "bias",
                      "the plug gauge's line-centre bias over diameters and placements, "
                      "as measured and corrected by the digital twin (true calibration, no "
                      "radius given)")
    q.add_argument("--diameters-mm", default="6,12,20,28", help="comma-separated")
    q.add_argument("--placements-mm", default="0:0,3:0,0:-3",
                   help="comma-separated x:y offsets from the axis")
    q.add_argument("--noise", choices=("none", "realistic"), default="none")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--twin-spp", type=int, default=DEFAULT_TWIN_SPP)
    q.add_argument("--rig", default="paper")
    q.set_defaults(func=cmd_study_bias)


def _add_design_space(studies) -> None:
    """``study design-space``."""
    q = _study_parser(studies, "design-space",
                      "α/β sweep: coverage, overlap, multiple reflections, "
                      "Monte Carlo radius uncertainty, heat maps, optimum")
    q.add_argument("--alpha-deg", default="20:70:5", help="START:STOP:STEP (inclusive) or a value")
    q.add_argument("--beta-deg", default="60:120:5", help="START:STOP:STEP (inclusive) or a value")
    q.add_argument("--draws", type=int, default=16, help="noise/speckle draws per rig (0: "
                   "geometry only)")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--scale", type=float, default=1.0, help="image scale (quick looks)")
    q.set_defaults(func=cmd_study_design_space)


def _add_algorithms(studies) -> None:
    """``study algorithms``."""
    q = _study_parser(studies, "algorithms",
                      "inverse vs classic triangulation and the three detectors "
                      "on the same images: bias, std, coverage, time")
    q.add_argument("--objects", default=None, help="comma-separated (default: plug-gauge, "
                   "alu-pipe, grooved-shaft, cable-8, cube)")
    q.add_argument("--repeats", type=int, default=3, help="noise draws per object and level")
    q.set_defaults(func=cmd_study_algorithms)


def add_demo_parser(sub) -> None:
    """``demo``: the main job in one command."""
    s = sub.add_parser("demo", help="run the main job: rig, coverage, objects, figures")
    s.add_argument("--out", default="lts360-demo", help="output directory (default ./lts360-demo)")
    s.add_argument("--radius-mm", type=float, default=10.0, help="section radius for the coverage")
    s.add_argument("--variant", default=None, help=VARIANT_HELP)
    s.add_argument("--no-render", action="store_true", help="skip the rendered frames")
    s.add_argument("--quick", action="store_true", help="skip the calibration and the "
                   "plug-gauge study (a few seconds instead of minutes)")
    s.add_argument("--gauge-trials", type=int, default=10, help="plug-gauge placements")
    _add_user_steps(s)
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_demo)
