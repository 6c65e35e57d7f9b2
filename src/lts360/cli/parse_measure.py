"""The parsers of the measuring commands: measure, compensate, score, inspect and calibrate
(their handlers in ``lts360.cli.commands``)."""

from __future__ import annotations

from lts360.cli.commands import (
    cmd_calibrate,
    cmd_compensate,
    cmd_inspect,
    cmd_measure,
    cmd_score,
)
from lts360.cli.usage import VARIANT_HELP
from lts360.inspect.local_events import DEFAULT_ARC_MM
from lts360.inspect.scan import DEFAULT_LUMP_MM
from lts360.inspect.uncertainty import DEFAULT_DRAWS
from lts360.recon.calibration.compensation import (
    DEFAULT_REFERENCE_HALF_WIDTH_MM,
    DEFAULT_REFERENCE_RADIUS_MM,
)
from lts360.recon.triangulation.acceptance import DEFAULT_MIN_COVERAGE
from lts360.recon.triangulation.band import (
    DEFAULT_FIXED_HALF_WIDTH_MM,
    DEFAULT_FIXED_RADIUS_MM,
    DEFAULT_FOLLOW_HALF_WIDTH_MM,
)
from lts360.recon.triangulation.grid import DEFAULT_R_STEP_MM, DEFAULT_THETA_STEP_DEG
from lts360.twin.debias import DEFAULT_AXIAL_REACH_MM, DEFAULT_TWIN_SPP


def add_measure_parsers(sub) -> None:
    """``measure``, ``compensate``, ``score``, ``inspect`` and ``calibrate``."""
    _add_measure_parser(sub)
    _add_compensate_parser(sub)
    _add_score_parser(sub)
    _add_inspect_parser(sub)
    _add_calibrate_parser(sub)


def _add_measure_parser(sub) -> None:
    """``measure``: frames, scans or images into a cloud."""
    s = sub.add_parser("measure", help="inverse triangulation of frames, scans or images")
    s.add_argument("inputs", nargs="+", help="frame directories, scan directories or image files")
    s.add_argument("--calibration", required=True,
                   help="calibration.json, or a rendered frame's frame.json (the true rig)")
    s.add_argument("--out", required=True, help="cloud.ply")
    s.add_argument("--method", choices=("inverse", "classic"), default="inverse",
                   help="inverse triangulation (paper §3.2) or the classical image-space baseline")
    s.add_argument("--peak", choices=("centroid", "gauss", "steger"), default="centroid")
    s.add_argument("--theta-step-deg", type=float, default=DEFAULT_THETA_STEP_DEG)
    s.add_argument("--r-step-mm", type=float, default=DEFAULT_R_STEP_MM)
    s.add_argument("--radius-mm", type=float, default=None,
                   help="nominal radius: search the fixed band radius ± --band-mm about the axis "
                        "(default: find the band from the image, over every radius the rig can "
                        f"image; the classic method then uses {DEFAULT_FIXED_RADIUS_MM:g})")
    s.add_argument("--band-mm", type=float, default=None,
                   help=f"radial search band ±: about --radius-mm (default "
                        f"{DEFAULT_FIXED_HALF_WIDTH_MM:g}), or about the profile found from the "
                        f"image (default {DEFAULT_FOLLOW_HALF_WIDTH_MM:g})")
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
    s.add_argument("--multipeak", choices=("on", "off"), default="on",
                   help="with --reject on: where a second line along a radial direction reaches "
                        "a fifth of the main one (interreflections), take the one the "
                        "section's other rows agree with, or call the row SEVERAL_PEAKS; "
                        "off: the strongest line, SEVERAL_PEAKS from half (default on)")
    s.add_argument("--min-coverage", type=float, default=DEFAULT_MIN_COVERAGE,
                   help="refuse (exit 3) a section that measures less than this share of the "
                        f"θ coverage its views predict (default {DEFAULT_MIN_COVERAGE:g}); a "
                        "section with no valid "
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
    s.add_argument("--twin-spp", type=int, default=DEFAULT_TWIN_SPP,
                   help=f"samples per pixel of the twin's render (default {DEFAULT_TWIN_SPP})")
    s.add_argument("--twin-axial-mm", type=float, default=DEFAULT_AXIAL_REACH_MM,
                   help="in a scan, sections within this axial distance give each section's twin "
                        f"its slope and curvature along the axis (default "
                        f"{DEFAULT_AXIAL_REACH_MM:.1f}; 0: a straight "
                        "prism)")
    s.add_argument("--twin-corners", choices=("off", "on"), default="off",
                   help="on: the twin restores the measured profile's sharp corners (its "
                        "direction turning >= 20° within ±0.4 mm: the faces beside it fitted and "
                        "intersected) where the sharpened twin measures more like the image "
                        "than the rounded one: a laser line rounds a sharp edge by its spot, "
                        "a twin of the rounded profile corrects about half of it (default off)")
    s.set_defaults(func=cmd_measure)


def _add_compensate_parser(sub) -> None:
    """``compensate``: the §4.4 offsets (and masters) into a calibration."""
    s = sub.add_parser("compensate", help="residual compensation (paper §4.4): the mirror "
                       "views' offsets from images of a round reference, into a calibration")
    s.add_argument("inputs", nargs="+", help="frame directories, scan directories or image "
                   "files of one round reference section (several: shots fitted together)")
    s.add_argument("--calibration", required=True, help="calibration.json to compensate")
    s.add_argument("--out", required=True, help="the compensated calibration.json")
    s.add_argument("--peak", choices=("centroid", "gauss", "steger"), default="centroid")
    s.add_argument("--theta-step-deg", type=float, default=DEFAULT_THETA_STEP_DEG)
    s.add_argument("--r-step-mm", type=float, default=DEFAULT_R_STEP_MM)
    s.add_argument("--radius-mm", type=float, default=DEFAULT_REFERENCE_RADIUS_MM,
                   help=f"the reference's nominal radius (default {DEFAULT_REFERENCE_RADIUS_MM:g})")
    s.add_argument("--band-mm", type=float, default=DEFAULT_REFERENCE_HALF_WIDTH_MM,
                   help=f"radial search band ± (default {DEFAULT_REFERENCE_HALF_WIDTH_MM:g})")
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


def _add_score_parser(sub) -> None:
    """``score``: a cloud against the truth of rendered frames."""
    s = sub.add_parser("score", help="score a measured cloud against the truth of rendered frames")
    s.add_argument("cloud", help="cloud.ply written by `lts360 measure`")
    s.add_argument("--truth", required=True, help="frame or scan directory written by `lts360 render`")
    s.add_argument("--out", required=True, help="metrics.json")
    s.set_defaults(func=cmd_score)


def _add_inspect_parser(sub) -> None:
    """``inspect``: the profile-gauge report of a cloud."""
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
    s.add_argument("--lump-mm", type=float, default=DEFAULT_LUMP_MM,
                   help=f"lump / neck-down threshold on Dmax / Dmin, and the depth a local "
                        f"lump or dent must be able to reach (default {DEFAULT_LUMP_MM:g})")
    s.add_argument("--lump-arc-mm", type=float, default=DEFAULT_ARC_MM,
                   help="σ (mm of arc) of the local lumps and dents the arc-matched detector "
                        f"looks for (default {DEFAULT_ARC_MM:g})")
    s.add_argument("--u-radial-mm", type=float, default=0.0,
                   help="type-B standard uncertainty of a radial offset common to a section "
                        "(the rig's error budget): 2u on diameters, u on deviations")
    s.add_argument("--filter-upr", type=float, default=None,
                   help="ISO 12181-2 Gaussian filter cut-off in [1, 1000] UPR before roundness "
                        "and diameters (default: by the diameter, 15/50/150/500/1500 UPR up to Ø "
                        "8/25/80/250 mm/above; docs/inspection.md)")
    s.add_argument("--filter", choices=("gaussian", "none"), default="gaussian",
                   help="none: no filter (extremes then carry more noise bias in U)")
    s.add_argument("--draws", type=int, default=DEFAULT_DRAWS,
                   help="calibration Monte Carlo draws")
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_inspect)


def _add_calibrate_parser(sub) -> None:
    """``calibrate``: camera, mirrors and laser plane from chessboards."""
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
    s.add_argument("--variant", default=None, help=VARIANT_HELP)
    s.set_defaults(func=cmd_calibrate)
