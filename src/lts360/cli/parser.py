"""The argument parser of every command (each sub-command's ``func`` is its handler)."""

from __future__ import annotations

import argparse

from lts360 import __version__
from lts360.cli.commands import (
    cmd_calibrate,
    cmd_compensate,
    cmd_inspect,
    cmd_measure,
    cmd_object,
    cmd_objects,
    cmd_render,
    cmd_rig,
    cmd_score,
)
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
from lts360.cli.design import add_design_parser
from lts360.cli.usage import _Parser


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="lts360", description="360° laser triangulation with mirrors: simulation "
                "and reconstruction testbed.")
    p.add_argument("--version", action="version", version=f"lts360 {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    s = sub.add_parser("objects", help="list every object with its parameters and defaults")
    s.set_defaults(func=cmd_objects)

    s = sub.add_parser("object", help="write an object's ground-truth mesh (world frame, mm)")
    s.add_argument("spec", help="NAME[:key=value,...], e.g. plug-gauge:d=19.9987,x=0.2,tilt_deg=1")
    s.add_argument("--out", required=True, help="output mesh file (.ply, .stl, .obj, .off, .glb)")
    s.set_defaults(func=cmd_object)

    s = sub.add_parser("rig", help="describe a rig and its coverage")
    s.add_argument("rig", nargs="?", default="paper", help="preset name (paper) or TOML file")
    s.add_argument("--coverage", action="store_true", help="print per-view θ windows and total coverage")
    s.add_argument("--radius-mm", type=float, default=10.0, help="section radius (default 10)")
    s.add_argument("--theta-step-deg", type=float, default=0.1, help="θ sampling (default 0.1°)")
    s.add_argument("--max-incidence-deg", type=float, default=80.0,
                   help="largest usable incidence angle of camera and laser (default 80°)")
    s.set_defaults(func=cmd_rig)

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
    s.add_argument("--max-scatter", type=int, choices=(0, 1, 2, 3), default=0,
                   help="interreflections of the laser light on the object (default 0: none)")
    s.add_argument("--roughness", type=float, default=None, metavar="ALPHA",
                   help="override the GGX roughness α of the object's material, in (0, 1]")
    s.add_argument("--pinhole", action="store_true", help="pinhole instead of the thin lens")
    s.add_argument("--exposure-us", type=float, default=None,
                   help="fixed exposure time (default: auto-exposure)")
    s.add_argument("--exposure-fraction", type=float, default=0.8,
                   help="auto-exposure target: brightest stripe pixels at this fraction of full scale")
    s.add_argument("--background-z-mm", type=float, default=None,
                   help="add a matte black base plate at this height (default: none)")
    s.add_argument("--sections", type=int, default=1, help="render a scan of N sections")
    s.add_argument("--pitch-mm", type=float, default=0.0, help="stage pitch of a scan (mm)")
    s.add_argument("--full-frame", action="store_true",
                   help="render every pixel (default: only the pixels that can hold laser light, "
                        "the rest get ambient light and sensor noise)")
    s.add_argument("--support", choices=("geometric", "pilot"), default="geometric",
                   help="how the rendered pixels are found: from the scene's geometry (direct "
                        "laser light) or a 4-spp pilot render of the integrator")
    m = s.add_argument_group("line motion (a moving object; needs --exposure-us)")
    m.add_argument("--speed-mm-s", type=float, default=0.0, help="feed along the axis, mm/s")
    m.add_argument("--vibration-mm", default=None, metavar="AX,AY",
                   help="lateral vibration amplitudes in x and y, mm")
    m.add_argument("--vibration-hz", type=float, default=0.0,
                   help="vibration frequency (a random vibration: its corner frequency)")
    m.add_argument("--vibration-kind", choices=("sine", "random"), default="sine",
                   help="sine (peak amplitude) or a seeded random walk (rms amplitude; a "
                        "band-limited Ornstein-Uhlenbeck process)")
    m.add_argument("--vibration-seed", type=int, default=0, help="the random vibration's path")
    m.add_argument("--rotation-deg-s", type=float, default=0.0, help="rotation about the axis")
    m.add_argument("--shutter", choices=("global", "rolling"), default="global")
    m.add_argument("--line-time-us", type=float, default=0.0,
                   help="rolling shutter: delay between rows' exposures (µs)")
    m.add_argument("--profile-rate-hz", type=float, default=None,
                   help="a moving scan: frames at this rate")
    m.add_argument("--encoder-pitch-mm", type=float, default=None,
                   help="a moving scan: a frame every this much feed")
    m.add_argument("--jitter-us", type=float, default=0.0, help="trigger timing jitter (σ, µs)")
    m.add_argument("--step-px", type=float, default=0.1,
                   help="sub-frames: no object point moves more than this many pixels in one")
    s.set_defaults(func=cmd_render)

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
    s.add_argument("--radius-mm", type=float, default=None,
                   help="nominal radius: search the fixed band radius ± --band-mm about the axis "
                        "(default: find the band from the image, over every radius the rig can "
                        "image; the classic method then uses 10)")
    s.add_argument("--band-mm", type=float, default=None,
                   help="radial search band ±: about --radius-mm (default 2), or about the "
                        "profile found from the image (default 1)")
    s.add_argument("--pitch-mm", type=float, default=None, help="stage pitch for bare images")
    s.add_argument("--compensate", action="store_true",
                   help="apply the calibration's residual compensation (paper §4.4)")
    s.add_argument("--backend", choices=("auto", "numpy", "llvm", "cuda"), default="auto",
                   help="auto: the Dr.Jit kernel for the centroid, numpy otherwise")
    s.add_argument("--continuity-k", type=float, default=None, metavar="K",
                   help="flag points off their view's local r(θ) (running median ±2°) by more "
                        "than K robust σ (at least 15 µm) as DISCONTINUOUS (default: off)")
    s.add_argument("--reject", choices=("on", "off"), default="on",
                   help="truth-free rejection of spurious points (inverse method): FADING "
                        "(within 0.5 mm of a stretch of a view's window where its line faded "
                        "out) and NOTCH (the profile 80 µm below its chord at ±0.5/±1 mm: a "
                        "notch the sheet does not resolve); default on")
    s.add_argument("--min-coverage", type=float, default=0.5,
                   help="refuse (exit 3) a section that measures less than this share of the "
                        "θ coverage its views predict (default 0.5); a section with no valid "
                        "point is always refused")
    s.add_argument("--bias-model", choices=("none", "twin"), default="none",
                   help="twin: correct the line-centre bias by measuring each section's digital "
                        "twin (its measured profile rendered noise-free through the calibrated "
                        "rig with --twin-rig's optics, laser and sensor) with the same plan and "
                        "subtracting its error per view and θ; adds ~1-3 s per section "
                        "(default none)")
    s.add_argument("--twin-rig", default=None,
                   help="rig file (preset or TOML) whose optics, laser, sensor and mirror "
                        "extents the twin uses; its geometry comes from --calibration "
                        "(default: the rig the calibration or frame records; an override must "
                        "have the recorded rig's design geometry)")
    s.add_argument("--twin-material", default="ground-steel",
                   help="the twin's surface (see lts360 objects; default ground-steel, the plug "
                        "gauge's)")
    s.add_argument("--twin-spp", type=int, default=64,
                   help="samples per pixel of the twin's render (default 64)")
    s.add_argument("--twin-axial-mm", type=float, default=1.0,
                   help="in a scan, sections within this axial distance give each section's twin "
                        "its slope and curvature along the axis (default 1.0; 0: a straight "
                        "prism)")
    s.set_defaults(func=cmd_measure)

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
    s.add_argument("--master-diameter-mm", default=None, metavar="D[,D2]",
                   help="mastering: the references' known diameters (one: per view a radial "
                        "offset beside the offsets; two or more, ≥ 1 mm apart: also a scale; "
                        "each shot is matched to its master); default: the paper's §4.4 only")
    s.add_argument("--master-u-mm", default=None, metavar="U[,U2]",
                   help="the masters' diameters' standard uncertainties (certificate; one per "
                        "diameter, or one for all; default 0)")
    s.add_argument("--bias-model", choices=("none", "twin"), default="none",
                   help="with masters: remove each reference's line-centre bias with its twin "
                        "before the fit (for measurements made with --bias-model twin; "
                        "default none)")
    s.add_argument("--twin-rig", default=None,
                   help="the twin's rig, if not the one the calibration records")
    s.set_defaults(func=cmd_compensate)

    s = sub.add_parser("score", help="score a measured cloud against the truth of rendered frames")
    s.add_argument("cloud", help="cloud.ply written by `lts360 measure`")
    s.add_argument("--truth", required=True, help="frame or scan directory written by `lts360 render`")
    s.add_argument("--out", required=True, help="metrics.json")
    s.set_defaults(func=cmd_score)

    s = sub.add_parser("inspect", help="profile-gauge report of a measured cloud: diameters, "
                       "ovality, roundness (ISO 12181), nominal deviation, trends, with U(k=2)")
    s.add_argument("cloud", help="cloud.ply written by `lts360 measure`")
    s.add_argument("--out", required=True, help="output directory (report.html, "
                   "inspection.json, sections.csv, figures), replaced as a whole")
    s.add_argument("--nominal", default=None, help="a diameter in mm (e.g. 32), object SPEC "
                   "(its analytic contour), CONTOUR.csv (x_mm,y_mm rows, closed) or DRAWING.dxf")
    s.add_argument("--diameter-mm", default=None, metavar="D±T",
                   help="size tolerance, e.g. 32±0.3: D min and D max within (exit 1 if not)")
    s.add_argument("--ovality-max-mm", type=float, default=None,
                   help="largest D max − D min (exit 1 if exceeded)")
    s.add_argument("--tolerance-mm", type=float, default=None,
                   help="profile tolerance zone width (ISO 1101): ± half of it about the nominal")
    s.add_argument("--upper-mm", type=float, default=None, help="upper deviation limit")
    s.add_argument("--lower-mm", type=float, default=None, help="lower deviation limit")
    s.add_argument("--calibration", default=None, help="the calibration.json the cloud was "
                   "measured with: its covariance gives the calibration uncertainty")
    s.add_argument("--truth", default=None, help="rendered frame or scan directory: true "
                   "values beside the measured ones")
    s.add_argument("--lump-mm", type=float, default=0.05,
                   help="lump / neck-down threshold on Dmax / Dmin (default 0.05)")
    s.add_argument("--u-radial-mm", type=float, default=0.0,
                   help="type-B standard uncertainty of a radial offset common to a section "
                        "(the rig's error budget): 2u on diameters, u on deviations")
    s.add_argument("--filter-upr", type=float, default=None,
                   help="ISO 12181-2 Gaussian filter cut-off in [1, 1000] UPR before roundness "
                        "and diameters (default: the standard's for the diameter)")
    s.add_argument("--filter", choices=("gaussian", "none"), default="gaussian",
                   help="none: no filter (extremes then carry more noise bias in U)")
    s.add_argument("--draws", type=int, default=20, help="calibration Monte Carlo draws")
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_inspect)

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
    s.set_defaults(func=cmd_calibrate)

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
    q.add_argument("--placement-mm", type=float, default=0.3, metavar="R",
                   help="placements drawn uniformly in a disc of radius R mm about the axis "
                   "(default 0.3); results are also reported against the distance from it")
    q.add_argument("--master", action="store_true",
                   help="master the compensation with the gauge's known diameter")
    q.add_argument("--bias-model", choices=("none", "twin"), default="none",
                   help="twin: each placement (and the master's shots) corrected by its twin")
    q.add_argument("--max-scatter", type=int, choices=(0, 1, 2, 3), default=0,
                   help="interreflections of the laser light in the gauge's images (default 0)")
    q.set_defaults(func=cmd_study_plug_gauge)

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
    q.add_argument("--placement-mm", type=float, default=0.3, metavar="R",
                   help="rendered placements drawn uniformly in a disc of radius R mm about the "
                   "axis (default 0.3); results are also reported against the distance from it")
    q.add_argument("--rig", default="paper", help="rig to render: 'paper' or a TOML file (the "
                   "one the calibration is of)")
    q.set_defaults(func=cmd_study_monte_carlo)

    q = study_parser("examples", "paper §4.6: the eight objects scanned with the paper's "
                     "sections and pitch, clouds, figures, error table")
    q.add_argument("--objects", default=None, help="comma-separated subset (default: all eight)")
    q.add_argument("--noise", choices=("none", "realistic"), default="realistic")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--calibration", default=None, help="measure with this calibration "
                   "(default: the frames' true one)")
    q.add_argument("--section-scale", type=float, default=1.0,
                   help="fraction of the paper's sections to scan (quick looks)")
    q.add_argument("--max-scatter", type=int, choices=(0, 1, 2, 3), default=0,
                   help="interreflections of the laser light (default 0: none)")
    q.set_defaults(func=cmd_study_examples)

    q = study_parser("line-speed", "a moving object: speed × exposure × shutter (global, "
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
    q.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_mono)")
    q.set_defaults(func=cmd_study_interreflection)

    q = study_parser("bias", "the plug gauge's line-centre bias over diameters and placements, "
                     "as measured and corrected by the digital twin (true calibration, no "
                     "radius given)")
    q.add_argument("--diameters-mm", default="6,12,20,28", help="comma-separated")
    q.add_argument("--placements-mm", default="0:0,3:0,0:-3",
                   help="comma-separated x:y offsets from the axis")
    q.add_argument("--noise", choices=("none", "realistic"), default="none")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--twin-spp", type=int, default=64)
    q.add_argument("--rig", default="paper")
    q.set_defaults(func=cmd_study_bias)

    q = study_parser("design-space", "α/β sweep: coverage, overlap, multiple reflections, "
                     "Monte Carlo radius uncertainty, heat maps, optimum")
    q.add_argument("--alpha-deg", default="20:70:5", help="START:STOP:STEP (inclusive) or a value")
    q.add_argument("--beta-deg", default="60:120:5", help="START:STOP:STEP (inclusive) or a value")
    q.add_argument("--draws", type=int, default=16, help="noise/speckle draws per rig (0: "
                   "geometry only)")
    q.add_argument("--spp", type=int, default=16)
    q.add_argument("--scale", type=float, default=1.0, help="image scale (quick looks)")
    q.set_defaults(func=cmd_study_design_space)

    q = study_parser("algorithms", "inverse vs classic triangulation and the three detectors "
                     "on the same images: bias, std, coverage, time")
    q.add_argument("--objects", default=None, help="comma-separated (default: plug-gauge, "
                   "alu-pipe, grooved-shaft, cable-8, cube)")
    q.add_argument("--repeats", type=int, default=3, help="noise draws per object and level")
    q.set_defaults(func=cmd_study_algorithms)

    add_design_parser(sub)

    s = sub.add_parser("demo", help="run the main job: rig, coverage, objects, figures")
    s.add_argument("--out", default="lts360-demo", help="output directory (default ./lts360-demo)")
    s.add_argument("--radius-mm", type=float, default=10.0, help="section radius for the coverage")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_mono)")
    s.add_argument("--no-render", action="store_true", help="skip the rendered frames")
    s.add_argument("--quick", action="store_true", help="skip the calibration and the "
                   "plug-gauge study (a few seconds instead of minutes)")
    s.add_argument("--gauge-trials", type=int, default=10, help="plug-gauge placements")
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_demo)
    return p
