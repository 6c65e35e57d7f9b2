"""The parsers of the scene commands: objects, object, rig and render (their handlers in
``lts360.cli.commands``)."""

from __future__ import annotations

from lts360.cli.commands import cmd_object, cmd_objects, cmd_render, cmd_rig
from lts360.cli.usage import VARIANT_HELP
from lts360.scenes.coverage import MAX_BOUNCES
from lts360.simulator.integrator import MAX_SCATTER


def add_scene_parsers(sub) -> None:
    """``objects``, ``object``, ``rig`` and ``render``."""
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
    _add_render_parser(sub)


def _add_render_parser(sub) -> None:
    """``render``: a frame or a scan, still or moving."""
    s = sub.add_parser("render", help="render a frame (or a scan) of an object in the rig")
    s.add_argument("--object", required=True, help="object SPEC, e.g. plug-gauge or cable-8:x=0.3")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--rig", default="paper", help="preset name or TOML file (default paper)")
    s.add_argument("--z-mm", type=float, default=0.0, help="section height on the object (mm)")
    s.add_argument("--noise", choices=("none", "realistic"), default="none")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--spp", type=int, default=16, help="samples per pixel (default 16)")
    s.add_argument("--variant", default=None,
                   help=VARIANT_HELP)
    s.add_argument("--laser", choices=("on", "off"), default="on")
    s.add_argument("--ambient", choices=("off", "dim", "bright"), default="off")
    s.add_argument("--scale", type=float, default=1.0, help="image scale in (0, 1]")
    s.add_argument("--max-bounces", type=int, choices=tuple(range(MAX_BOUNCES + 1)), default=2,
                   help="mirror reflections followed on camera and laser paths (default 2)")
    s.add_argument("--max-scatter", choices=("auto",) + tuple(str(k) for k in range(MAX_SCATTER + 1)),
                   default="auto",
                   help="interreflections of the laser light on the object: bounces 0-3, or auto "
                        "(default): 1 for a shiny material (specular weight >= 0.5: machined or "
                        "polished aluminium, brass, glossy plastic), 0 otherwise")
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
    s.add_argument("--support", choices=("full", "geometric", "hull", "pilot"),
                   default="geometric",
                   help="which pixels are rendered: only those that can hold laser light, found "
                        "from the scene's geometry (default: the stripe for direct laser light; "
                        "with --max-scatter > 0 every pixel that can see a shape, as 'hull') "
                        "or from a 4-spp pilot render, the rest getting ambient light and "
                        "sensor noise; or every one (full)")
    s.add_argument("--full-frame", dest="support", action="store_const", const="full",
                   help="render every pixel (the same as --support full)")
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
