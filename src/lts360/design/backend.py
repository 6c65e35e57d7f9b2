"""The array back ends of the design package: numpy for checks, Dr.Jit for the model.

The small-matrix algebra (:mod:`lts360.design.smallmat`), the calibration's information
blocks (:mod:`lts360.design.calib_fisher`) and the model's stages take an ``ops`` object and
call only its functions, so one piece of code runs on numpy arrays (:data:`NUMPY_OPS`) and
inside a recorded Dr.Jit program with reverse-mode gradients (:class:`DrJitOps`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["NumpyOps", "NUMPY_OPS", "DrJitOps", "drjit_ops"]


class NumpyOps:
    """The array functions the core needs, for numpy arrays (float64)."""

    name = "numpy"

    @staticmethod
    def sqrt(x):
        return np.sqrt(x)

    @staticmethod
    def sin(x):
        return np.sin(x)

    @staticmethod
    def cos(x):
        return np.cos(x)

    @staticmethod
    def block_sum(x, n: int):
        """Sums of consecutive blocks of ``n`` elements: ``(m n,) → (m,)``."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 1 or x.size % n:
            raise ValueError(f"block_sum: need a 1-D array whose size is a multiple of {n}, "
                             f"got shape {x.shape}")
        return x.reshape(-1, n).sum(axis=1)

    @staticmethod
    def gather(x, index):
        """``x[index]``."""
        return np.asarray(x, dtype=float)[np.asarray(index)]


NUMPY_OPS = NumpyOps()


class DrJitOps:
    """The same functions for ``drjit.llvm.ad.Float64`` arrays, the Dr.Jit types the model
    uses (``F`` Float64, ``V3`` Array3f64, ``U`` UInt32, ``B`` Bool) and the few compound
    operations of its stages.  Imports Dr.Jit when made."""

    name = "drjit"

    def __init__(self):
        import drjit as dr
        from drjit.llvm.ad import Array3f64, Bool, Float64, UInt32

        self.dr, self.F, self.V3, self.U, self.B = dr, Float64, Array3f64, UInt32, Bool

    def sqrt(self, x):
        return self.dr.sqrt(x)

    def sin(self, x):
        return self.dr.sin(x)

    def cos(self, x):
        return self.dr.cos(x)

    def block_sum(self, x, n: int):
        return self.dr.block_sum(x, n)

    def gather(self, x, index):
        return self.dr.gather(type(x), x, index)

    def sig(self, x):
        """Smooth step of a margin in widths: 0 below −1, 1 above +1, the C¹ cubic
        ``t² (3 − 2t)`` between (a handful of JIT operations, exact 0/1 outside)."""
        t = self.dr.clip(0.5 * x + 0.5, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)

    def relu2(self, x):
        m = self.dr.maximum(x, 0.0)
        return m * m

    def reflect_point(self, p, n, d):
        return p - n * (2.0 * (self.dr.dot(p, n) - d))

    def reflect_dir(self, v, n):
        return v - n * (2.0 * self.dr.dot(v, n))


def drjit_ops() -> DrJitOps:
    """A :class:`DrJitOps` (imports Dr.Jit on call)."""
    return DrJitOps()
