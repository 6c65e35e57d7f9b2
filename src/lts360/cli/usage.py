"""What every command shares: the usage error (one line, exit 2), the parser that raises it,
the Mitsuba variant and a progress bar."""

from __future__ import annotations

import argparse

__all__ = ["UsageError", "VARIANT_HELP"]

#: The help of every --variant option (the choice is lts360.simulator.render.default_variant's).
VARIANT_HELP = ("Mitsuba variant (default: cuda_ad_mono where a CUDA device is usable, else "
                "llvm_ad_mono)")


class UsageError(Exception):
    """Bad input from the user: one line on stderr, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2, no usage dump
        raise UsageError(f"{self.prog}: error: {message}")


def _set_variant(name: str | None) -> str:
    import mitsuba as mi

    from lts360.simulator.render import default_variant

    if name is None:
        name = default_variant()
    if name not in mi.variants():
        raise UsageError(f"--variant: {name!r} is not compiled into this Mitsuba; choose one of "
                         f"{', '.join(mi.variants())}")
    try:
        mi.set_variant(name)
    except Exception as exc:  # e.g. a CUDA variant on a machine without a GPU
        raise UsageError(f"--variant: {name} cannot run here ({str(exc).splitlines()[0]})") from None
    return name


def _progress(items, desc):
    try:
        from tqdm import tqdm
    except ImportError:  # progress bars are a nicety
        return items
    return tqdm(items, desc=desc, unit="frame")
