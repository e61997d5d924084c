"""What the energy ledger and the wear need beyond the cells' end contents: the impulse of
the cells that slid (``_impulse_fix`` for the inner cells, ``_edge_impulse`` for an edge
cell), the energy an edge cell dissipated (``_edge_dissipation``), and the tick's ledger step
(``_ledger``)."""

from __future__ import annotations

import math

from numba import njit

from .cells import _cells, _edge, _edge_limit, _edges, _inner_limit, _overlap
from .layout import (
    JIT,
    JIT_INLINE,
    JIT_INLINE_PY,
    L_IA,
    L_IB,
    L_LIMIT,
    L_U0,
    ST_DRIVE,
    ST_EXT,
    ST_IMP,
    ST_REL,
    ST_RUNNER,
    W_A,
    W_L,
)


@njit(inline="always", **JIT)
def _uN_integral(zc, d, inv3R):
    """F(zc) = d zc - zc^3 / (3R), the integral of uN = d - z^2 / R from the patch centre to
    zc (inside the contact, |zc| <= a)."""
    return zc * (d - zc * zc * inv3R)


@njit(inline="always", **JIT)
def _uN_antiderivative(z, a, d, inv3R):
    """H(z) with H' = F(clamp(z, -a, a)) (``_uN_integral``): d z^2 / 2 - z^4 / (12 R) inside
    the contact, linear outside (continuous)."""
    zc = min(max(z, -a), a)
    return zc * zc * (0.5 * d - 0.25 * zc * zc * inv3R) + _uN_integral(zc, d, inv3R) * (z - zc)


@njit(**JIT_INLINE_PY)
def _limit_integral(xL, xR, c0, u, dt, a, d, inv3R, muEG):
    """Time integral over a sub-step of the friction limit of the cell [xL, xR] (muEG times
    the integral of uN over its part in contact, muEG (F(clamp(xR - c)) - F(clamp(xL - c))))
    while the patch centre moves from c0 at speed u: exact, as differences of
    ``_uN_antiderivative`` over 1/u.  Where the patch moves less than 1e-5 a in the
    sub-step (the differences would cancel) the midpoint rule, within 1e-10 of it."""
    h = u * dt
    if abs(h) <= 1e-5 * a:
        cm = c0 + 0.5 * h
        return (
            muEG
            * dt
            * (
                _uN_integral(min(max(xR - cm, -a), a), d, inv3R)
                - _uN_integral(min(max(xL - cm, -a), a), d, inv3R)
            )
        )
    c1 = c0 + h
    H = _uN_antiderivative
    return (
        muEG
        * (
            (H(xR - c0, a, d, inv3R) - H(xR - c1, a, d, inv3R))
            - (H(xL - c0, a, d, inv3R) - H(xL - c1, a, d, inv3R))
        )
        / u
    )


@njit(**JIT_INLINE_PY)
def _edge_impulse(U0, Ut, Li, I_free, s, xL, xR, c0, u, dt, a, d, inv3R, muEG):
    """Time integral over a sub-step of an edge cell's content, for the ledger's impulse in
    sub-steps where cells slid.  U0: content at the start; Ut: unclipped content at the end,
    Li the limit there; I_free: the unclipped content's exact time integral (``_walk``'s IA +
    IB s); IL: the limit's exact time integral (``_limit_integral``).
    * At its limit at the start on the side the creep pushes it (or entering the contact in
      the sub-step) and beyond it at the end, or leaving the contact: it slid all through,
      +-IL (exact; the smaller of IL and |I_free| for one that entered stuck and started to
      slide within the sub-step, both bounds of its integral).
    * Inside its limits at both ends: I_free (exact if it stays inside in between), at most
      IL in size (a cell that leaves the contact can go beyond its limit in between and end
      with nothing).
    * Inside at the start, beyond at the end on the same side: the free path up to the time
      where the straight lines between the ends of |content| - limit cross, the limit's exact
      integral from there.
    * Otherwise (it stops sliding, or reverses): its clipped path taken straight between the
      ends (``_clip_path``)."""
    L0 = _edge_limit(xL, xR, c0, a, d, inv3R, muEG)[0]
    IL = _limit_integral(xL, xR, c0, u, dt, a, d, inv3R, muEG)
    sg = Ut if Ut != 0.0 else U0
    held = abs(U0) >= L0 * (1.0 - 1e-9) and U0 * sg >= 0.0 and U0 * s >= 0.0
    over = abs(Ut) > Li
    if held and (over or (U0 != 0.0 and Li == 0.0)):
        # at most the free path's integral too (the clipped content is at most both): an
        # entering cell that stuck for part of the sub-step is nearer it than its limit
        return math.copysign(min(IL, abs(I_free)) if I_free * sg > 0.0 else IL, sg)
    if not over and not (held and U0 != 0.0):
        return math.copysign(min(abs(I_free), IL), I_free)
    g0 = abs(U0) - L0
    if over and g0 < 0.0 and U0 * Ut >= 0.0:
        tau = -g0 / ((abs(Ut) - Li) - g0)  # in [0, 1): the end is beyond (g1 > 0)
        cx = c0 + u * tau * dt
        Lx = _edge_limit(xL, xR, cx, a, d, inv3R, muEG)[0]
        rest = _limit_integral(xL, xR, cx, u, (1.0 - tau) * dt, a, d, inv3R, muEG)
        return math.copysign(0.5 * tau * (abs(U0) + Lx) * dt + rest, Ut)
    return _clip_path(U0, Ut, L0, Li) * dt


@njit(**JIT_INLINE)
def _edge_dissipation(U0, Ut, Uc, Li, I_free, s, xL, xR, c0, c1, u, dt, a, d, inv3R, muEG):
    """Energy an edge cell dissipated over a sub-step with finite friction: its elastic energy
    at the start plus the creep work s times the integral of its content (``_edge_impulse``)
    less its elastic energy at the end (content Uc, clipped).  With finite friction the
    continuum's material leaves the contact at zero deflection (its friction limit vanishes
    at the edge), so what the cell releases there is slip work too, done in a layer about
    |creep| (G*/E*) R / mu wide, mostly thinner than a cell: counted so, the wear converges
    from coarse grids."""
    l0 = _overlap(xL, xR, c0, a)
    l1 = _overlap(xL, xR, c1, a)
    e0 = 0.5 * U0 * U0 / l0 if l0 > 0.0 else 0.0
    e1 = 0.5 * Uc * Uc / l1 if l1 > 0.0 else 0.0
    if l1 > 0.0 and abs(Ut) <= Li and abs(U0) < _edge_limit(xL, xR, c0, a, d, inv3R, muEG)[0]:
        imp = I_free  # in contact, inside its limits at both ends (the usual case)
    else:
        imp = _edge_impulse(U0, Ut, Li, I_free, s, xL, xR, c0, u, dt, a, d, inv3R, muEG)
    D = e0 + s * imp - e1
    return D if D > 0.0 else 0.0


@njit(inline="always", **JIT)
def _path_kinks(a, b, L0, L1):
    """A cell that slid (|b| > L1) from a start that is not at (or beyond) its start limit L0
    on the side it ends on: inside its limits or at the other one (a creep reversal), so
    that its path bends within the sub-step.  A cell that stays at its limit (the usual
    sliding cell) follows the limit, whose mean the trapezoid gives.  Within 1e-9 of L0 a
    start counts as at the limit: the start limit the commit's census estimates
    (``_limit_drift``) differs from the limit that clipped the cell in the last sub-step by
    rounding, and a start that much inside its limit changes the impulse by nothing
    measurable."""
    return abs(b) > L1 and not (a * b > 0.0 and abs(a) >= L0 * (1.0 - 1e-9))


@njit(inline="always", **JIT)
def _clip_path(a, b, L0, L1):
    """Mean over a sub-step of a content moving straight from a towards b, clipped to a
    friction limit +-L going straight from L0 to L1: clip(a + (b - a) t, -L(t), L(t)), t in
    [0, 1].  The content is inside the limits between the roots of the two linear functions
    x - L and x + L and at a limit outside them: at most three pieces, each linear in t and
    integrated exactly by its midpoint value."""
    d = b - a
    dL = L1 - L0
    gp = d - dL  # x - L = (a - L0) + gp t
    gm = d + dL  # x + L = (a + L0) + gm t
    tp = -(a - L0) / gp if gp != 0.0 else 2.0
    tm = -(a + L0) / gm if gm != 0.0 else 2.0
    c1 = min(max(min(tp, tm), 0.0), 1.0)
    c2 = min(max(max(tp, tm), 0.0), 1.0)
    m = 0.0
    for lo, hi in ((0.0, c1), (c1, c2), (c2, 1.0)):
        t = 0.5 * (lo + hi)
        lim = L0 + dL * t
        m += (hi - lo) * min(max(a + d * t, -lim), lim)
    return m


@njit(**JIT)
def _impulse_fix(W, j0, j1, x_lo, dx, c0, muEG, d, inv3R, dxdt, s):
    """For the ledger's impulse after a commit: the sum over the inner cells j0..j1 that slid
    without staying at their limit (``_path_kinks``) of the mean
    of their clipped path (``_clip_path``: content from A = U at the start towards
    A + dx dt s, limit from its value at the start, at patch centre c0, to the end, L_LIMIT)
    less the mean of its end points (the trapezoid, which the sub-step's impulse takes for
    every cell; exact for a cell at its limit all through).  Exact for an inner cell up to
    the limit's curvature in time (quadratic in the patch centre).  Called only where the
    commit counted such a cell (``_commit``'s census).  Returns (the sum, the signed number
    of such cells: +1 for a cell ending at +L, -1 at -L)."""
    fix = 0.0
    n_sign = 0.0
    for i in _cells(j0, j1 + 1):
        a = W[W_A, i]
        b = a + dxdt * s
        L1 = W[W_L + L_LIMIT, i]
        L0 = _inner_limit(x_lo, dx, i, c0, muEG, d, inv3R)
        if _path_kinks(a, b, L0, L1):
            fix += _clip_path(a, b, L0, L1) - 0.5 * (a + math.copysign(L1, b))
            n_sign += math.copysign(1.0, b)
    return fix, n_sign


@njit(**JIT_INLINE)
def _ledger(st, rows, cells, geo, c0, s0, s, runner, sums, commit, mu, mass, load):
    """The tick's ledger step: the sub-step's impulse of T and the works it does, added to
    the state.  ``runner``: (vb, v0, v1, lam, F) of the runner step; ``sums``: (SIA, SIB,
    E0, E1, E2, SU) of the build pass; ``commit``: (clipped, dimp, T1_in) of the commit.
    Returns the impulse."""
    vb, v0, v1, lam, F = runner
    SIA, SIB, E0, E1, E2, SU = sums
    clipped, dimp, T1_in = commit
    _U, A, B, L = rows
    i0, i1, j0, j1 = cells
    x_lo, dx, inv_dx, inv3R, muEG, a, d, u, dt, dxdt = geo
    if clipped and mu is not None:
        imp_edge = 0.0  # the edge cells' contents integrated over the sub-step
        if a > 0.0:
            for k in _edges(i0, i1, j0, j1):
                i = _edge(k, j0, j1)
                xL = x_lo + i * dx
                Ut = A[i] + B[i] * s
                I_free = L[L_IA, i] + L[L_IB, i] * s
                imp_edge += _edge_impulse(
                    L[L_U0, i],
                    Ut,
                    L[L_LIMIT, i],
                    I_free,
                    s,
                    xL,
                    xL + dx,
                    c0,
                    u,
                    dt,
                    a,
                    d,
                    inv3R,
                    muEG,
                )
        # some cells slid (finite friction).  Inner cells: the trapezoid, exact for a
        # cell that sticks (its content is linear in time) and, with the curvature
        # term, for one at its limit all through; plus for each inner cell whose path
        # bends its clipped path's integral less its trapezoid (at a creep reversal
        # its content flips from one limit to the other early in the sub-step, which
        # the trapezoid alone misses: first order there).  Edge cells: each its own
        # integral (``_edge_impulse``: exact for a cell that sticks or slides all
        # through)
        imp = (0.5 * (SU + T1_in) + dimp) * dt + imp_edge
    else:
        imp = SIA + SIB * s  # no slip: exact integral of T over the sub-step
    work_r = vb * imp
    if mass is not None and mass > 0.0 and not clipped:
        # a free runner on a stuck contact: its impulse and work from its own
        # equation (exact on the force law's linear piece, where the cells' integrals
        # assume a constant creep rate over the sub-step), as far as the step is the
        # exact one (lam; backward Euler's runner sees the cells' constant creep
        # rate).  Where cells slid the cells' own integrals are the better impulse
        # (the piece's linear force ramp misses the limits' motion: 1% of the drive
        # work at one cell per sub-step)
        imp = lam * (mass * (v1 - v0) - F * dt) + (1.0 - lam) * imp
        work_r = lam * (0.5 * mass * (v1 - v0) * (v1 + v0) - F * vb * dt) + (1.0 - lam) * work_r
    st[ST_IMP] += imp
    if mu is None:
        st[ST_REL] += E0 + s * (E1 + s * E2)
    st[ST_DRIVE] += s0 * imp
    st[ST_RUNNER] += work_r
    if load is not None:
        st[ST_EXT] += load * vb * dt
    return imp
