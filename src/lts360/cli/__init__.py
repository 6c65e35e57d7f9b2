"""The ``lts360`` command line: thin wrappers that parse, validate, call the library, print.

Usage errors (bad arguments, bad specs, bad rig files) print one line on stderr and exit 2.
``parser`` builds the command tree from each group's parsers (``parse_scene``, ``parse_measure``,
``parse_studies``, ``design``); ``commands``, ``studies`` and ``design`` hold the handlers,
``usage`` the error they raise.
"""

from __future__ import annotations

import sys

from lts360.cli.parser import build_parser
from lts360.cli.usage import UsageError

__all__ = ["main", "build_parser"]


def main(argv: list[str] | None = None) -> int:
    from lts360.scenes.rig import RigError

    try:
        args = build_parser().parse_args(argv)
        args.argv = list(sys.argv[1:] if argv is None else argv)  # the command, for reports
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(str(exc) if str(exc).startswith("lts360") else f"lts360: error: {exc}", file=sys.stderr)
        return 2
    except (RigError, ValueError, FileNotFoundError) as exc:
        print(f"lts360: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
