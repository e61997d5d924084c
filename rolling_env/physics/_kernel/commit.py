"""The commit of a sub-step: every cell's content at the creep rate the runner step found,
clipped to its friction limit with the slip work, and the build pass over the inner cells
that precedes it.  The loops over the inner cells are compiled with ``_FM_INNER``
(reordered sums) as functions of their own; ``_commit_cells`` and ``_commit_edges`` are the
tick's commit step."""

from __future__ import annotations

import math

from numba import njit, uint64

from .cells import _cells, _clip_slope, _edge, _edges, _inner_limit, _overlap, _slide, _trailing
from .layout import (
    _FM_INNER,
    JIT,
    JIT_INLINE,
    L_IA,
    L_IB,
    L_LIMIT,
    L_QLIM,
    L_U0,
    ST_ITER,
    W_A,
    W_B,
    W_L,
    W_U,
)
from .ledger import _edge_dissipation, _impulse_fix, _path_kinks
from .runner import _converged, _solve_runner


@njit(fastmath=_FM_INNER, **JIT)
def _build_inner(W, j0, j1, x_lo, dx, c1, muEG, d, inv3R, dxdt, sv0, mu, mass):
    """Build pass over the inner cells j0..j1 (A = U; friction limits; runner equation at
    v0).  Returns (SU, Tt0, dT0)."""
    SU = 0.0
    Tt0 = 0.0
    dT0 = 0.0
    for i in _cells(j0, j1 + 1):
        Ai = W[W_U, i]
        W[W_A, i] = Ai  # B = dx dt is written only for _solve_bracketed, which reads it
        SU += Ai
        if mu is not None:
            Li = _inner_limit(x_lo, dx, i, c1, muEG, d, inv3R)
            W[W_L + L_LIMIT, i] = Li
            if mass is not None:
                Ut, dU = _clip_slope(Ai + dxdt * sv0, Li, dxdt)
                Tt0 += Ut
                dT0 += dU
    return SU, Tt0, dT0


_DOWN = 2.0**-26  # _commit's count of a cell that slid down (see there)


@njit(fastmath=_FM_INNER, **JIT)
def _commit(W, i0, i1, j0, j1, dxdt, s, inv_dx, mu, mass, edges, census, drift):
    """Commit of the cells i0..i1, U = A + B s clipped to the friction limit.  Returns (T1,
    Ta, slip, n_slid, n_kinks, n_sign).  ``edges`` None: i0..i1 are inner cells (B = dx dt,
    overlap dx).
    ``edges`` True: every cell of the contact, the inner cells j0..j1 as above and the edge
    cells with the B and limit per unit overlap the build pass stored for them, in one loop
    (a select per cell instead of a separate scalar loop over the few edge cells: 7% of the
    default env step; for the inner cells alone the selects and their loads cost more than
    they save).  ``census``: None (counts returned 0), or with the ledger and ``edges`` None
    the pair (alpha, beta) of ``_limit_drift``, for the ledger's impulse: the number of cells
    that slid, of those the ones whose path bends in the sub-step (``_path_kinks``, which
    ``_impulse_fix`` then integrates) and the signed number that slid (+1 at +L, -1 at -L;
    less ``_impulse_fix``'s signed count of the bent ones, those held at their limit all
    through, for the curvature term), counted in this loop rather than in a pass of their
    own, with the start limit of cell i as its end limit less alpha + beta i (a pass of its
    own, or the start limit from its quadratic, made ``Drive.run`` with friction about 30%
    slower; this census, with the scalar passes it calls for, 20%: ``simulate`` at r = 0.3,
    10 periods, 0.012 against 0.010 s).  The cells that slid up and down are counted in one
    float sum, 1 per cell at +L and 2^-26 per cell at -L, exact for rows of up to 2^26 cells
    (the grid has at most 2e7): two integer counts, or a signed count beside n_slid, kept
    LLVM from vectorising the loop as well (``Drive.run`` 4-20% slower, measured).
    ``drift``: with friction, the pair (alpha, beta) of ``_limit_drift`` (the inner cells'
    limits at the start of the sub-step are L - (alpha + beta i)): a sliding inner cell's slip
    work takes the mean of its limit over the part of the sub-step in which it slides, from
    the moment its content (straight in time from A to A + B s) meets the limit (straight in
    time from its start to its end value): the trapezoid in time for a cell at its limit all
    through, exact for a straight limit.  Charging the whole sub-step's mean to a cell that
    starts sliding within it overcharged the falling limits near the trailing edge (the Eq. 32
    episodes' wear up to 1.6% high at the shipped sub-steps, 6% at a quarter of them).  The
    edge cells' mean limit per unit overlap is the build pass's ``L_QLIM``."""
    T1 = 0.0
    Ta = 0.0
    slip = 0.0
    slid = 0.0
    n_kinks = 0
    j_lo = uint64(j0)  # i0 <= j0 <= i1 + 1
    n_in = uint64(max(j1 - j0 + 1, 0))
    for i in _cells(i0, i1 + 1):
        Bi = dxdt
        if edges is not None:
            inner = (i - j_lo) < n_in  # unsigned: wraps to a large number below j0
            Bm = W[W_B, i]  # loaded unconditionally so that the choices are selects
            Bi = dxdt if inner else Bm
        Ut = W[W_A, i] + Bi * s
        if mu is not None:
            Li = W[W_L + L_LIMIT, i]
            dLi = drift[0] + drift[1] * float(i)
            # a cell that starts inside its limit slides only after its content meets the
            # limit, at tau of the sub-step (content and limit both straight in time): its
            # slip work takes the mean limit over (tau, 1), not over the whole sub-step
            a0 = W[W_A, i] if Ut > 0.0 else -W[W_A, i]
            den = (abs(Ut) - Li) - (a0 - (Li - dLi))
            tau = min(max((Li - dLi - a0) / den if den > 0.0 else 0.0, 0.0), 1.0)
            q = (Li - 0.5 * dLi * (1.0 - tau)) * inv_dx
            if edges is not None:
                qm = W[W_L + L_QLIM, i]
                q = q if inner else qm
            if census is not None:
                L0 = Li - (drift[0] + drift[1] * i)
                n_kinks += 1 if _path_kinks(W[W_A, i], Ut, L0, Li) else 0
            Ut, work, over = _slide(Ut, Li, q)
            slip += work
            if census is not None:
                slid += (1.0 if Ut > 0.0 else _DOWN) if over else 0.0
            if mass is not None:
                Ta += abs(Ut)
        W[W_U, i] = Ut
        T1 += Ut
    n_up = math.floor(slid)
    n_down = (slid - n_up) * (1.0 / _DOWN)
    return T1, Ta, slip, int(n_up + n_down), n_kinks, n_up - n_down


@njit(fastmath=_FM_INNER, **JIT)
def _stuck_inner(W, j0, j1):
    """Number of the inner cells j0..j1 that stick (see ``_stuck_length``), as a float."""
    n_stuck = 0.0
    for i in _cells(j0, j1 + 1):
        Li = W[W_L + L_LIMIT, i]
        n_stuck += 1.0 if abs(W[W_U, i]) - Li < -1e-12 * Li else 0.0
    return n_stuck


@njit(**JIT)
def _stuck_length(W, i0, i1, j0, j1, x_lo, dx, c1, a):
    """Length of the contact whose cells stick (below their friction limit by more than
    1e-12 of it) after a commit: inner cells count dx, edge cells their overlap with the
    contact centred at c1.  Called for the last sub-step of a tick only."""
    U = W[W_U]
    L = W[W_L:]
    stuck = _stuck_inner(W, j0, j1) * dx
    for k in _edges(i0, i1, j0, j1):
        i = _edge(k, j0, j1)
        Li = L[0, i]
        if abs(U[i]) - Li < -1e-12 * Li:
            xL = x_lo + i * dx
            stuck += _overlap(xL, xL + dx, c1, a)
    return stuck


@njit(inline="always", **JIT)
def _limit_drift(x_lo, dx, c0, c1, muEG, inv3R):
    """(alpha, beta) with L1 - L0 = alpha + beta i for the friction limit of inner cell i at
    patch centres c1 (end) and c0 (start) (``_inner_limit``: muEG dx (d - S(z) / (3R)),
    S(z) = z^2 + z (z + dx) + (z + dx)^2, z = x_lo + i dx - c; S(z + h) - S(z) =
    3 h (2 z + h + dx) with h = c1 - c0), for a filter: equal to the quadratics up to
    rounding (and the clamp at 0, which inner cells do not reach)."""
    h = c1 - c0
    k = muEG * dx * inv3R * 3.0 * h
    return k * (2.0 * (x_lo - c1) + h + dx), k * 2.0 * dx


@njit(**JIT_INLINE)
def _commit_cells(W, cells, geo, path, s, mu, mass, ledger):
    """The tick's commit step, first part: the contents at creep rate s, clipped to their
    friction limits, in the branch-free loop of ``_commit`` (a cell beyond its limit slides
    to it, adding the slip work; the others add exactly 0 to it): in the env with friction
    every cell of the contact (inner cells: B = dx dt and overlap dx; edge cells: the B and
    the limit per unit overlap of the build pass), otherwise the inner cells (the edge cells
    follow in ``_commit_edges``).  Returns (T1, Ta, slip, clipped, dimp, T1_in): with the
    ledger and friction, whether a cell slid, the inner cells' correction of the trapezoid
    impulse and their T at the end."""
    i0, i1, j0, j1 = cells
    x_lo, dx, inv_dx, inv3R, muEG, a, d, u, dt, dxdt = geo
    drift = (0.0, 0.0)
    if mu is not None:
        drift = _limit_drift(x_lo, dx, path[0], path[1], muEG, inv3R)
    dimp = 0.0
    clipped = False
    T1_in = 0.0  # with the ledger and friction: T of the inner cells at the end
    if ledger is None and mu is not None:
        T1, Ta, slip, _ns, _nk, _nh = _commit(
            W, i0, i1, j0, j1, dxdt, s, inv_dx, mu, mass, True, None, drift
        )
    elif ledger is not None and mu is not None:
        T1, Ta, slip, n_slid, n_kinks, n_held = _commit(
            W, j0, j1, j0, j1, dxdt, s, inv_dx, mu, mass, None, True, drift
        )
        clipped = n_slid > 0
        if n_kinks > 0:
            dimp, n_bent = _impulse_fix(W, j0, j1, x_lo, dx, path[0], muEG, d, inv3R, dxdt, s)
            n_held -= n_bent
        # the inner cells that stayed at their limit follow it, a quadratic in time
        # whose curvature (-2 muEG dx u^2 / R for the +limit) the trapezoid misses
        dimp += n_held * (muEG * dx * inv3R * 0.5) * (u * dt) * (u * dt)
        T1_in = T1
    else:
        T1, Ta, slip, _ns, _nk, _nh = _commit(
            W, j0, j1, j0, j1, dxdt, s, inv_dx, mu, mass, None, None, drift
        )
    return T1, Ta, slip, clipped, dimp, T1_in


@njit(**JIT_INLINE)
def _commit_edges(rows, cells, geo, path, s, mu, mass, ledger, acc):
    """The tick's commit step, second part: the edge cells.  In the env with friction
    ``_commit`` took them, and the trailing ones' slip work is replaced by their dissipation
    (``_edge_dissipation``); otherwise each is committed here, one by one.  ``acc``: (T1, Ta,
    slip, clipped) of ``_commit_cells``, returned with the edge cells added."""
    U, A, B, L = rows
    i0, i1, j0, j1 = cells
    x_lo, dx, inv_dx, inv3R, muEG, a, d, u, dt, dxdt = geo
    c0, c1 = path
    T1, Ta, slip, clipped = acc
    if ledger is None and mu is not None:
        if a > 0.0 and u != 0.0:
            for k in _edges(i0, i1, j0, j1):
                i = _edge(k, j0, j1)
                if not _trailing(i, j0, u):
                    continue
                xL = x_lo + i * dx
                Ut0 = A[i] + B[i] * s
                Li = L[L_LIMIT, i]
                _u, work, _o = _slide(Ut0, Li, L[L_QLIM, i])
                I_free = L[L_IA, i] + L[L_IB, i] * s
                U0 = L[L_U0, i]
                xR = xL + dx
                D = _edge_dissipation(
                    U0, Ut0, U[i], Li, I_free, s, xL, xR, c0, c1, u, dt, a, d, inv3R, muEG
                )
                slip += D - work
        return T1, Ta, slip, clipped
    for k in _edges(i0, i1, j0, j1):
        i = _edge(k, j0, j1)
        Ut = A[i] + B[i] * s
        if mu is not None:
            Ut0 = Ut
            Ut, work, over = _slide(Ut, L[0, i], L[L_QLIM, i])
            clipped |= over
            if a > 0.0 and u != 0.0 and _trailing(i, j0, u):
                xL = x_lo + i * dx
                Li = L[L_LIMIT, i]
                I_free = L[L_IA, i] + L[L_IB, i] * s
                U0 = L[L_U0, i]
                xR = xL + dx
                slip += _edge_dissipation(
                    U0, Ut0, Ut, Li, I_free, s, xL, xR, c0, c1, u, dt, a, d, inv3R, muEG
                )
            else:
                slip += work
            if mass is not None:
                Ta += abs(Ut)
        U[i] = Ut
        T1 += Ut
    return T1, Ta, slip, clipped


@njit(**JIT_INLINE)
def _root_checked(rows, cells, dxdt, s0, runner, T1, Ta, mu, mass, st, iters):
    """After a commit with friction and a free runner: verify the runner step's one-step
    root (g(vb) vanishes unless the step crossed a kink of the force law); where it does not
    hold, solve for the root (``_solve_runner``) for a second commit.  ``runner``: (vb, fast,
    vref, Fs, h) of ``_runner``.  Returns (done, vb, iters)."""
    _U, A, B, L = rows
    i0, i1, j0, j1 = cells
    vb, fast, vref, Fs, h = runner
    if mu is None or mass is None or not fast:
        return True, vb, iters
    # verify the one-step root: g(vb) vanishes unless the step crossed a kink
    iters += 1.0
    g1 = mass * (vb - vref) - h * (T1 + Fs)
    if _converged(g1, mass, vb, vref, h, Ta, Fs):
        return True, vb, iters
    st[ST_ITER] = iters
    B[j0 : j1 + 1] = dxdt
    vb = _solve_runner(A, B, L, i0, i1, s0, vref, vb, mass, Fs, h, st)
    return False, vb, st[ST_ITER]
