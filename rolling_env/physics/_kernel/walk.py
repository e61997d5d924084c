"""The exact creep integration of an edge cell over a sub-step (``_walk``; ``_walk_content``
without the ledger's integrals): U_end = A + B s for the creep rate s."""

from __future__ import annotations

import math

from numba import njit

from .cells import _overlap
from .layout import JIT, JIT_INLINE


@njit(inline="always", **JIT)
def _forward(xL, xR, c0, u):
    """Cell bounds and patch centre in the frame where the patch moves towards +x."""
    if u > 0.0:
        return xL, xR, c0
    return -xR, -xL, -c0


@njit(inline="always", **JIT)
def _duration(dist, inv_au, au):
    """Time the patch takes for ``dist`` at speed ``au``: times 1/|u| (``_inv_speed``), or
    divided by |u| where 1/|u| would overflow (``inv_au`` = 0)."""
    return dist * inv_au if inv_au > 0.0 else dist / au


@njit(inline="always", **JIT)
def _inv_speed(u):
    """1/|u| for ``_walk``, or 0 where it would overflow (|u| <= 1e-300)."""
    au = abs(u)
    return 1.0 / au if au > 1e-300 else 0.0


@njit(**JIT_INLINE)
def _walk_entry(B, IA, IB, A, p, q, pL, a, au, inv_au):
    """Piece [b0, b1) of ``_walk``: the leading edge inside the cell, the overlap growing at
    |u| (dU/dt = s l).  Returns (B, IA, IB)."""
    dtp = _duration(q - p, inv_au, au)
    la = p + a - pL
    IA += A * dtp
    IB += B * dtp + 0.5 * la * dtp * dtp + au * dtp * dtp * dtp / 6.0
    B += dtp * (la + 0.5 * au * dtp)
    return B, IA, IB


@njit(**JIT_INLINE)
def _walk_both(A, B, IA, IB, e0, e1, e2, a, au, dtp):
    """Piece [b1, b2) of ``_walk`` for a contact narrower than the cell (both edges inside it:
    d(U/l)/dt = s - |u| (U/l) / l, l = 2a).  Returns (A, B, IA, IB, e0, e1, e2)."""
    ell = 2.0 * a
    k = au / ell
    em1 = -math.expm1(-k * dtp)  # 1 - exp(-k dt)
    em2 = -math.expm1(-2.0 * k * dtp)  # 1 - exp(-2 k dt)
    g = ell / k
    # U(t) = alpha(t) + s beta(t), alpha = A e^{-kt}, beta = g + (B - g) e^{-kt}
    IA += A * em1 / k
    IB += B * em1 / k + g * (dtp - em1 / k)
    c2 = 0.5 * au / (ell * ell)
    e0 += c2 * A * A * em2 / (2.0 * k)
    e1 += c2 * 2.0 * A * (g * em1 / k + (B - g) * em2 / (2.0 * k))
    e2 += c2 * (g * g * dtp + 2.0 * g * (B - g) * em1 / k + (B - g) * (B - g) * em2 / (2.0 * k))
    A = A * (1.0 - em1)
    B = B * (1.0 - em1) + g * em1
    return A, B, IA, IB, e0, e1, e2


@njit(**JIT_INLINE)
def _walk_exit(A, B, IA, IB, e0, e1, e2, p, q, pR, a, au, dtp):
    """Piece [b2, b3) of ``_walk``: the trailing edge inside the cell, released material
    carrying the mean (d(U/l)/dt = s).  Returns (A, B, IA, IB, e0, e1, e2)."""
    la = pR + a - p
    lb = pR + a - q
    if la > 0.0:
        r = 1.0 / la
        mA = A * r
        mB = B * r
        J0 = la * dtp - 0.5 * au * dtp * dtp
        J1 = 0.5 * la * dtp * dtp - au * dtp * dtp * dtp / 3.0
        IA += mA * J0
        IB += mB * J0 + J1
        h = 0.5 * au
        e0 += h * mA * mA * dtp
        e1 += h * 2.0 * mA * (mB * dtp + 0.5 * dtp * dtp)
        e2 += h * (mB * mB * dtp + mB * dtp * dtp + dtp * dtp * dtp / 3.0)
        A = mA * lb
        B = (mB + dtp) * lb
    else:
        A = 0.0
        B = 0.0
    return A, B, IA, IB, e0, e1, e2


@njit(inline="always", **JIT)
def _walk(U0, xL, xR, c0, a, u, inv_au, dt):
    """Exact creep integration of one cell over a sub-step (uniform-cell model).

    Returns (A, B, IA, IB, e0, e1, e2) with
    U_end = A + B s, integral of U dt = IA + IB s, released elastic energy (G* = 1)
    = e0 + e1 s + e2 s^2.  The patch centre moves from c0 to c0 + u dt.  ``inv_au`` is 1/|u|
    (``_inv_speed``: computed once per tick) or 0 where that would overflow (|u| below
    1e-300), and then the walk divides by |u|.
    """
    A = U0
    B = 0.0
    IA = 0.0
    IB = 0.0
    e0 = 0.0
    e1 = 0.0
    e2 = 0.0
    if u == 0.0:
        ell = _overlap(xL, xR, c0, a)
        return A, ell * dt, A * dt, 0.5 * ell * dt * dt, 0.0, 0.0, 0.0
    au = abs(u)
    pL, pR, p = _forward(xL, xR, c0, u)
    p_end = p + au * dt
    b0 = pL - a
    b1 = min(pR - a, pL + a)
    b2 = max(pR - a, pL + a)
    b3 = pR + a
    wide = (pR - pL) <= 2.0 * a
    if p_end <= b0 or p >= b3:
        A = 0.0 if p >= b3 else A
        return A, 0.0, A * dt, 0.0, 0.0, 0.0, 0.0
    # walk the pieces [b0, b1) entry, [b1, b2) full or both, [b2, b3) exit
    if p < b0:
        p = b0  # no contact before b0: nothing changes (U0 is 0 there)
    while p < p_end:
        if p < b1:
            q = min(b1, p_end)
            B, IA, IB = _walk_entry(B, IA, IB, A, p, q, pL, a, au, inv_au)
        elif p < b2:
            q = min(b2, p_end)
            dtp = _duration(q - p, inv_au, au)
            if wide:
                ell = pR - pL
                IA += A * dtp
                IB += B * dtp + 0.5 * ell * dtp * dtp
                B += ell * dtp
            else:
                A, B, IA, IB, e0, e1, e2 = _walk_both(A, B, IA, IB, e0, e1, e2, a, au, dtp)
        elif p < b3:
            q = min(b3, p_end)
            dtp = _duration(q - p, inv_au, au)
            A, B, IA, IB, e0, e1, e2 = _walk_exit(A, B, IA, IB, e0, e1, e2, p, q, pR, a, au, dtp)
        else:
            q = p_end
            A = 0.0
            B = 0.0
        p = q
    return A, B, IA, IB, e0, e1, e2


@njit(inline="always", **JIT)
def _walk_content(U0, xL, xR, c0, a, u, inv_au, dt):
    """(A, B) of ``_walk`` (U_end = A + B s) without the integrals the ledger needs, in
    closed form instead of a walk over the pieces: with the contact wider than the cell the
    content grows by s times the integral of the overlap until the trailing edge enters the
    cell, and from there its mean deflection grows by s (one division and no loop).  A
    contact narrower than the cell takes ``_walk``.  Agrees with ``_walk`` to round-off
    (tests/test_kernel_paths.py)."""
    if u == 0.0:
        return U0, _overlap(xL, xR, c0, a) * dt
    au = abs(u)
    pL, pR, p = _forward(xL, xR, c0, u)
    ell = pR - pL
    if ell > 2.0 * a:
        A, B, _ia, _ib, _e0, _e1, _e2 = _walk(U0, xL, xR, c0, a, u, inv_au, dt)
        return A, B
    p_end = p + au * dt
    b0 = pL - a
    b1 = pR - a
    b2 = pL + a
    b3 = pR + a
    if p_end <= b0:
        return U0, 0.0
    if p >= b3:
        return 0.0, 0.0
    p = max(p, b0)
    pm = min(p_end, b2)  # end of the growing part (entry, then full)
    e_hi = min(pm, b1)
    B = max(e_hi - p, 0.0) * (0.5 * (e_hi + p) - b0) + ell * max(pm - max(p, b1), 0.0)
    B = _duration(B, inv_au, au)
    A = U0
    if p_end > b2:  # the trailing edge crossed into the cell: d(U/l)/dt = s from pe on
        pe = max(p, b2)
        la = b3 - pe
        lb = max(b3 - p_end, 0.0)
        dte = _duration(min(p_end, b3) - pe, inv_au, au)
        r = lb / la if la > 0.0 else 0.0  # la = 0: cell below the coordinates' rounding step
        A = A * r
        B = B * r + dte * lb
    return A, B
