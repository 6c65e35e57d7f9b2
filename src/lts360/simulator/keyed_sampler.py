"""Samples keyed to the pixel: common random numbers for renders of nearly the same scene.

Mitsuba seeds a wavefront's samplers lane by lane, so a pixel's samples depend on where it
sits in the list of pixels rendered.  Two renders on two slightly different pixel lists (the
twin of one image with two calibrations, whose plans read slightly different pixels) then
draw independent noise, and their difference carries the render noise of both.
:class:`KeyedSampler` gives every pixel samples that are a function of the pixel, the seed
and the sample index only: a randomly shifted rank-1 lattice per pixel (Korobov generating
vector ``z_d = a^d mod n`` with ``a`` the integer nearest ``n / φ`` coprime to ``n``; every
dimension shifted by its own uniform number, hashed from the pixel, the seed and the
dimension with TEA).  Each point of a randomly shifted lattice is uniform on the unit cube,
so a pixel's mean is an unbiased estimate of its integral, and the lattice stratifies the
film position and the lens aperture as a jittered pattern does.

It offers what :mod:`lts360.simulator.integrator` asks of a sampler (``next_1d``,
``next_2d``), and no more: the renders that use it call that integrator from Python
(:func:`lts360.simulator.render.render_pixels` with ``sampler="keyed"``).
"""

from __future__ import annotations

import math

__all__ = ["KeyedSampler", "lattice_multiplier"]

#: TEA rounds for the shifts (Mitsuba's default for its own sampler seeds).
_ROUNDS = 4


def lattice_multiplier(n: int) -> int:
    """The Korobov multiplier for ``n`` points: the integer nearest ``n / φ`` that is coprime
    to ``n`` (searched outwards; 1 for ``n`` ≤ 2).  Its 2-D lattice ``(s/n, a·s/n mod 1)`` is
    the Fibonacci lattice's kin: every point alone in its row and column of an ``n × n`` grid."""
    n = int(n)
    if n < 1:
        raise ValueError(f"lattice_multiplier: n must be >= 1, got {n}")
    if n <= 2:
        return 1
    g = n / ((1 + math.sqrt(5)) / 2)
    base = int(round(g))
    for step in range(n):
        for a in (base - step, base + step):
            if 1 <= a < n and math.gcd(a, n) == 1:
                return a
    return 1


class KeyedSampler:
    """Sample ``s`` of pixel ``key`` along dimension ``d``: ``frac(z_d · s / n + Δ(key, seed,
    d))``, ``n`` the samples per pixel.

    Parameters
    ----------
    key : mitsuba UInt32 (lanes)
        Each lane's pixel key (its linear index on the film).
    sample : mitsuba UInt32 (lanes)
        Each lane's sample index in ``[0, spp)``.
    spp : int
    seed : int, in [0, 2^32)
    """

    def __init__(self, key, sample, spp: int, seed: int) -> None:
        import mitsuba as mi

        if not (isinstance(spp, int) and spp >= 1):
            raise ValueError(f"KeyedSampler: spp must be an integer >= 1, got {spp!r}")
        if not (isinstance(seed, int) and 0 <= seed < 2**32):
            raise ValueError(f"KeyedSampler: seed must be an integer in [0, 2^32), got {seed!r}")
        self._key = key
        self._s = mi.UInt32(sample)
        self._n = int(spp)
        self._a = lattice_multiplier(spp)
        self._z = 1  # z_d = a^d mod n
        self._seed = int(seed)
        self._dim = 0

    def _next(self):
        import drjit as dr
        import mitsuba as mi

        word = mi.sample_tea_32(self._seed, self._dim, _ROUNDS)[0]  # (seed, dimension)
        # opaque: the seed's words are kernel data, not literals (a literal per seed would
        # compile a new kernel for every seed: every section of a scan, every Monte Carlo draw)
        shift = mi.sample_tea_float32(self._key, dr.opaque(mi.UInt32, int(word)), _ROUNDS)
        x = mi.Float((self._s * self._z) % self._n) * (1.0 / self._n) + shift  # s·z < 2^32
        self._dim += 1
        self._z = (self._z * self._a) % self._n
        return x - dr.floor(x)

    def next_1d(self, active=True):
        return self._next()

    def next_2d(self, active=True):
        import mitsuba as mi

        u = self._next()
        return mi.Point2f(u, self._next())
