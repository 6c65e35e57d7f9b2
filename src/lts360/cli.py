"""The ``lts360`` command line: thin wrappers that parse, validate, call the library, print.

Usage errors (bad arguments, bad specs, bad rig files) print one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

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


def _cmd_demo(args) -> int:
    from lts360.experiments.demo import run_demo

    run_demo(Path(args.out), radius_mm=args.radius_mm)
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

    s = sub.add_parser("demo", help="run the main job: rig, coverage, objects, figures")
    s.add_argument("--out", default="lts360-demo", help="output directory (default ./lts360-demo)")
    s.add_argument("--radius-mm", type=float, default=10.0, help="section radius for the coverage")
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
