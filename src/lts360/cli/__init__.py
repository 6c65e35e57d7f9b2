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

__all__ = ["main", "run", "build_parser"]


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


def run() -> None:
    """The ``lts360`` console script (and ``python -m lts360.cli``): :func:`main`, then exit
    without the interpreter's teardown.

    Everything is written and closed when :func:`main` returns; what is left is freeing the
    ~1500 modules a command imports (Mitsuba, Open3D, matplotlib, xarray, …), 0.4–0.75 s
    measured after ``lts360 demo``.  The exit handlers still run (temporary folders, pools,
    logging) and the standard streams are flushed first; with a non-daemon thread still alive
    the interpreter exits as usual (it joins it).  A reader that closes the pipe early ends the
    command with status 1 and no traceback."""
    import atexit
    import os
    import threading

    try:
        code = main()
    except BrokenPipeError:  # the reader left (``lts360 objects | head``): no traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 1
    if any(t is not threading.main_thread() and not t.daemon for t in threading.enumerate()):
        sys.exit(code)
    atexit._run_exitfuncs()  # what the interpreter's exit runs, in order
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BrokenPipeError:  # the reader left before the last of the output
            code = code or 1
        except (OSError, ValueError):  # a closed stream: nothing more to say
            pass
    os._exit(code)
