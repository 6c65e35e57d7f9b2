"""Smooth validity of a light path through the mirrors, in Dr.Jit (the design model's).

:func:`trace` is the differentiable counterpart of the numpy test
:func:`lts360.geometry.mirror_path.path_valid`: the path from a section point through an
ordered sequence of mirrors to a target (the camera or the laser) meets each mirror inside
its rectangle on its reflecting side, and no segment is blocked by the object cylinder or
another mirror.  Each condition is a smooth step of its margin (:meth:`DrJitOps.sig`), so
the product tends to the hard test as the widths shrink (tests/design/test_paths.py).
"""

from __future__ import annotations

__all__ = ["segment_clear", "trace"]


def segment_clear(o, a, b, centre_xy, r, mirrors, skip, cyl: bool, w_mm):
    """Soft 'not blocked' of segments a→b by the object cylinder and the other mirrors."""
    dr = o.dr
    s = 1.0
    if cyl:
        ax, ay = a.x - centre_xy[0], a.y - centre_xy[1]
        dx, dy = b.x - a.x, b.y - a.y
        dd = dr.maximum(dx * dx + dy * dy, 1e-18)
        t = dr.clip(-(ax * dx + ay * dy) / dd, 0.0, 1.0)
        qx, qy = ax + t * dx, ay + t * dy
        s = s * o.sig((dr.sqrt(qx * qx + qy * qy + 1e-18) - r) / w_mm)
    for k, m in enumerate(mirrors):
        if k in skip:
            continue
        da, db = dr.dot(a, m.n) - m.d, dr.dot(b, m.n) - m.d
        crosses = o.sig(-da / w_mm) * o.sig(db / w_mm) + o.sig(da / w_mm) * o.sig(-db / w_mm)
        den = da - db
        den = dr.select(dr.abs(den) > 1e-12, den, 1e-12)
        p = a + (b - a) * (da / den)
        q = p - m.c
        qu, qv = dr.dot(q, m.u), dr.dot(q, m.v)
        inside = (o.sig((m.half_w - qu) / w_mm) * o.sig((m.half_w + qu) / w_mm)
                  * o.sig((m.half_h - qv) / w_mm) * o.sig((m.half_h + qv) / w_mm))
        s = s * (1.0 - crosses * inside)
    return s


def trace(o, X, target, seq, mirrors, centre_xy, r, w_mm, w_cos):
    """Soft validity of the path X → mirrors(seq) → target.

    Returns ``(soft, leave_dir, arrive_dir, length_mm)``.
    """
    dr = o.dr
    virtual = target
    for k in reversed(seq):
        virtual = o.reflect_point(virtual, mirrors[k].n, mirrors[k].d)
    delta = virtual - X
    length = dr.norm(delta)
    direction = delta / length
    leave = direction
    s = 1.0
    p, first, prev = X, True, None
    for k in seq:
        m = mirrors[k]
        denom = dr.dot(direction, m.n)
        s = s * o.sig(-denom / w_cos)
        den = dr.select(dr.abs(denom) > 1e-12, denom, -1e-12)
        t = (m.d - dr.dot(p, m.n)) / den
        s = s * o.sig(t / w_mm)
        hit = p + direction * t
        q = hit - m.c
        qu, qv = dr.dot(q, m.u), dr.dot(q, m.v)
        s = s * (o.sig((m.half_w - qu) / w_mm) * o.sig((m.half_w + qu) / w_mm)
                 * o.sig((m.half_h - qv) / w_mm) * o.sig((m.half_h + qv) / w_mm))
        skip = {k} if prev is None else {k, prev}
        s = s * segment_clear(o, p, hit, centre_xy, r, mirrors, skip, not first, w_mm)
        direction = o.reflect_dir(direction, m.n)
        p, first, prev = hit, False, k
    s = s * segment_clear(o, p, target, centre_xy, r, mirrors,
                          set() if prev is None else {prev}, not first, w_mm)
    return s, leave, direction, length
