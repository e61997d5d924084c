"""The compiled control tick (``_tick``) as a loop of named steps, and ``run_ticks``.

Per sub-step: ``_sub_cells`` (the cells the contact touches; the inner ones, inside it all
through), ``_build`` (every cell's end content as A + B s), ``_runner`` (the runner step:
vb, the runner's mean velocity, and so the creep rate s = s0 - vb), ``_commit_cells`` and
``_commit_edges`` (the contents at s clipped to their friction limits, with the slip work),
``_root_checked`` (with friction, the runner step verified against the runner equation: a
kink of the force law crossed sends the sub-step to ``_solve_runner`` and a second commit)
and, with the energy ledger, ``_ledger``.  Each step is a function of its own that LLVM
inlines into the tick (``layout.JIT_INLINE``: numba's ``forceinline``), so the tick is one
compiled body with no call per step; the steps, like the tick, have no floating-point flags
(only the cell loops that stay calls, ``_build_inner`` and ``_commit``, reorder their sums).

Passes over the cells per sub-step: with infinite friction one build pass (A, B) and the
commit; with finite friction and a free runner the build pass also evaluates the runner
equation at v0, one Newton step gives the root of the piece active there, and the commit
verifies it (a kink crossed sends the sub-step to ``_solve_bracketed`` and commits again).
Cells inside the contact for the whole sub-step (A = U, B = dx dt) take a branch-free build
loop (``_build_inner``); only the few edge cells are integrated one by one (``_walk`` with
the ledger, ``_walk_content`` without).  The commit takes every cell in one branch-free loop
(``_commit``) in the env with friction; elsewhere (no friction, or the ledger) the inner cells
take that loop and the edge cells a scalar one.  The loops' sums may be reordered so that
LLVM vectorises them.  B of the inner cells is never written by the build pass (the commit
uses dx dt for them): it holds stale values except just before a call of
``_solve_bracketed`` (finite friction), which reads it."""

from __future__ import annotations

import math

from numba import njit

from .cells import (
    _cell_floor,
    _clip_slope,
    _contact_range,
    _edge,
    _edge_limit,
    _edges,
    _index,
    _inner_range,
    _inner_tol,
    _level_grid,
    _normal_content,
    _overlap,
    _trailing,
)
from .commit import _build_inner, _commit_cells, _commit_edges, _root_checked, _stuck_length
from .grid import _regrid, _set_radius, _target_level
from .layout import (
    FLAG_GRID,
    FLAG_NONFINITE,
    JIT,
    JIT_INLINE,
    L_IA,
    L_IB,
    L_QLIM,
    L_U0,
    N_LCOL,
    OUT_C,
    OUT_IMP,
    OUT_N,
    OUT_SLIP,
    OUT_STICK,
    OUT_T,
    OUT_VS,
    OUT_XS,
    P_E_OVER_G,
    P_LEVELS,
    P_R,
    P_X_LO,
    ST_A,
    ST_C,
    ST_D,
    ST_FLAG,
    ST_ITER,
    ST_LEVEL,
    ST_SLIP,
    ST_T,
    ST_TIME,
    ST_VS,
    ST_XS,
    ST_XSPH,
    W_A,
    W_B,
    W_L,
    W_U,
)
from .ledger import _ledger
from .runner import _end_velocity, _runner
from .walk import _inv_speed, _walk, _walk_content


@njit(**JIT_INLINE)
def _new_contact(W, st, p, a, d, mu, ledger):
    """The tick's indentation d (half-width a) into force: on a level grid the new contact's
    level first (``_regrid``), so that a cut and a snap act on its cells, then the new radius
    (``_set_radius``).  Returns the snap's slip work."""
    levels = int(p[P_LEVELS])
    if levels > 0:
        lv = _target_level(a, levels, int(st[ST_LEVEL]))
        if lv != int(st[ST_LEVEL]):
            _regrid(W, st, p, lv, ledger)
    return _set_radius(W, st, p, a, d, mu, ledger)


@njit(**JIT_INLINE)
def _sub_cells(st, c0, c1, a, x_lo, dx, inv_dx, n, tol):
    """The cells a sub-step touches, i0..i1 (the union of the contact at c0 and at c1; a
    contact that reached the end of the row is flagged), and of them the inner cells j0..j1,
    inside the contact all through (none: j1 = j0 - 1)."""
    f0 = _cell_floor(min(c0, c1) - a, x_lo, inv_dx)  # as _contact_range at the end
    f1 = _cell_floor(max(c0, c1) + a, x_lo, inv_dx)
    if not (f0 >= 0.0 and f1 <= n - 1.0):
        st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_GRID
    i0 = _index(f0, 0, n)
    i1 = _index(f1, -1, n - 1)
    full_lo = max(c0, c1) - a
    full_hi = min(c0, c1) + a
    if a > 0.0:
        j0, j1 = _inner_range(i0, i1, full_lo, full_hi, x_lo, dx, inv_dx, tol)
    else:
        j0 = i1 + 1
        j1 = i1
    return i0, i1, j0, j1


@njit(**JIT_INLINE)
def _build(W, rows, cells, geo, path, inv_au, sv0, mu, mass, ledger):
    """The tick's build step: each cell's content at the end of the sub-step as A + B s (s
    the creep rate), the inner cells (A = U, B = dx dt) in one branch-free loop
    (``_build_inner``), then the edge cells one by one (``_walk``, ``_walk_content``), with
    their friction limits; with friction and a free runner also the runner equation at v0
    (sv0 = s0 - v0).  Returns (SA, SB, SU, SIA, SIB, E0, E1, E2, Tt0, dT0): the sums of A and
    B, the inner cells' U, the ledger's integrals of T (IA + IB s) and released energy (E0 +
    E1 s + E2 s^2, infinite friction), and T and dT/ds at v0."""
    U, A, B, L = rows
    i0, i1, j0, j1 = cells
    x_lo, dx, inv_dx, inv3R, muEG, a, d, u, dt, dxdt = geo
    c0, c1 = path
    SA = 0.0
    SB = 0.0
    SIA = 0.0
    SIB = 0.0
    n_in = j1 - j0 + 1
    SU, Tt0, dT0 = _build_inner(W, j0, j1, x_lo, dx, c1, muEG, d, inv3R, dxdt, sv0, mu, mass)
    if n_in > 0:
        SA += SU
        SB += n_in * dxdt
        if ledger is not None:
            SIA += SU * dt
            SIB += n_in * 0.5 * dxdt * dt
    E0 = 0.0
    E1 = 0.0
    E2 = 0.0
    for k in _edges(i0, i1, j0, j1):
        i = _edge(k, j0, j1)
        xL = x_lo + i * dx
        xR = xL + dx
        if a > 0.0 and ledger is None and (mu is None or not _trailing(i, j0, u)):
            Ai, Bi = _walk_content(U[i], xL, xR, c0, a, u, inv_au, dt)
        elif a > 0.0 and ledger is None:
            # with friction what an edge cell releases is wear (``_edge_dissipation``):
            # its start content and the integral of its content
            Ai, Bi, IA, IB, _e0, _e1, _e2 = _walk(U[i], xL, xR, c0, a, u, inv_au, dt)
            L[L_U0, i] = U[i]
            L[L_IA, i] = IA
            L[L_IB, i] = IB
        elif a > 0.0:
            Ai, Bi, IA, IB, e0, e1, e2 = _walk(U[i], xL, xR, c0, a, u, inv_au, dt)
            SIA += IA
            SIB += IB
            if mu is None:
                E0 += e0
                E1 += e1
                E2 += e2
            else:
                L[L_U0, i] = U[i]
                L[L_IA, i] = IA
                L[L_IB, i] = IB
        else:
            Ai = 0.0
            Bi = 0.0
        A[i] = Ai
        B[i] = Bi
        SA += Ai
        SB += Bi
        if mu is not None:
            # friction limit at the end of the sub-step and the limit per unit overlap
            # (the commit's slip work: the slid distance is the excess over the overlap)
            Li, q = _edge_limit(xL, xR, c1, a, d, inv3R, muEG)
            # the slip work's limit per unit overlap: the mean of the sub-step's two ends
            L[L_QLIM, i] = 0.5 * (q + _edge_limit(xL, xR, c0, a, d, inv3R, muEG)[1])
            L[0, i] = Li
            if mass is not None:
                Ut, dU = _clip_slope(Ai + Bi * sv0, Li, Bi)
                Tt0 += Ut
                dT0 += dU
    return SA, SB, SU, SIA, SIB, E0, E1, E2, Tt0, dT0


@njit(**JIT_INLINE)
def _tick_in(st):
    """The state the sub-steps advance, (c1, v1, T1, xs, xsph, time, slip_acc, iters), read
    into locals: ``st`` may alias the cell arrays for the compiler, which would reload and
    store it around every cell loop (``_tick_out`` writes them back)."""
    return (
        st[ST_C],
        st[ST_VS],
        st[ST_T],
        st[ST_XS],
        st[ST_XSPH],
        st[ST_TIME],
        st[ST_SLIP],
        st[ST_ITER],
    )


@njit(**JIT_INLINE)
def _tick_out(st, out, state, EG, a, d, stuck, mu):
    """Write the state the sub-steps advanced, ``state`` = (c1, v1, T1, xs, xsph, time,
    slip_acc, iters, imp_tick, slip_tick), back to ``st`` and the tick's outputs to ``out``;
    flag a non-finite result."""
    c1, v1, T1, xs, xsph, time, slip_acc, iters, imp_tick, slip_tick = state
    st[ST_C] = c1
    st[ST_VS] = v1
    st[ST_T] = T1
    st[ST_XS] = xs
    st[ST_XSPH] = xsph
    st[ST_TIME] = time
    st[ST_SLIP] = slip_acc
    st[ST_ITER] = iters
    out[OUT_T] = T1
    out[OUT_IMP] = imp_tick  # 0 without the ledger
    out[OUT_VS] = v1
    out[OUT_XS] = xs
    out[OUT_SLIP] = slip_tick
    out[OUT_C] = c1
    out[OUT_N] = 4.0 / 3.0 * EG * a * d
    # stuck fraction of the contact length (counted after the last sub-step's commit)
    if mu is None or a == 0.0:
        out[OUT_STICK] = 1.0 if a > 0.0 else 0.0
    else:
        # the cells' overlaps sum to 2a only to round-off: a wholly stuck contact reads 1
        f = stuck / (2.0 * a)
        out[OUT_STICK] = 1.0 if f > 1.0 - 1e-12 else f
    if not (
        math.isfinite(T1) and math.isfinite(v1) and math.isfinite(xs) and math.isfinite(slip_tick)
    ):
        st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_NONFINITE


@njit(**JIT)
def _tick(W, st, p, d, u, v, vs_presc, mu, mass, load, n_sub, dt, out, ledger):
    """Advance one control tick of n_sub sub-steps with piecewise-constant inputs.

    d: indentation, u: omega R (signed), v: sphere translation rate (signed),
    vs_presc: runner velocity when ``mass is None`` (prescribed runner), else ignored.
    mu / mass / load: float or None (infinite friction / prescribed runner / no load).
    W: work array of shape (``work_rows(mu is not None, ledger is not None)``, n): U, A, B
    and, with finite friction, L = W[W_L:] (friction limit, the released-energy coefficients
    and the limit per unit overlap of edge cells; with the ledger also the rows L_U0, L_IA,
    L_IB of ``_edge_impulse``).
    ledger: True keeps the impulse and the energy ledger (``ST_IMP``, ``ST_REL``,
    ``ST_DRIVE``, ``ST_RUNNER``, ``ST_EXT``, ``ST_SNAP``, ``OUT_IMP``); None leaves them out
    (the env needs neither: its observation, reward and info use T, v*, x*, the slip work and
    the stuck fraction, which are the same either way, to round-off:
    tests/test_kernel_paths.py).  The steps of a sub-step: see the module docstring.
    """
    R = p[P_R]
    EG = p[P_E_OVER_G]
    x_lo = p[P_X_LO]
    inv3R = 1.0 / (3.0 * R)
    muEG = 0.0
    if mu is not None:
        muEG = mu * EG
    a = math.sqrt(R * d) if d > 0.0 else 0.0
    inv_au = _inv_speed(u)
    # (patch travel per sub-step / contact radius)^2, for the runner step's blend (``_blend``)
    tr2 = (u * dt / a) * (u * dt / a) if a > 0.0 else 0.0
    slip_tick = _new_contact(W, st, p, a, d, mu, ledger)
    dx, n = _level_grid(W.shape[1], st, p)
    rows = (W[W_U, :n], W[W_A, :n], W[W_B, :n], W[W_L:, :n])  # U, A, B, L
    inv_dx = 1.0 / dx
    geo = (x_lo, dx, inv_dx, inv3R, muEG, a, d, u, dt, dx * dt)
    tol = _inner_tol(x_lo, inv_dx, n)
    s0 = u - v
    F = 0.0
    if load is not None:
        F = load
    imp_tick = 0.0
    stuck = 0.0
    c1, v1, T1, xs, xsph, time, slip_acc, iters = _tick_in(st)
    for k_sub in range(n_sub):
        c0 = c1
        c1 = c0 + u * dt
        v0 = v1
        path = (c0, c1)
        cells = _sub_cells(st, c0, c1, a, x_lo, dx, inv_dx, n, tol)
        SA, SB, SU, SIA, SIB, E0, E1, E2, Tt0, dT0 = _build(
            W, rows, cells, geo, path, inv_au, s0 - v0, mu, mass, ledger
        )
        built = (SA, SB, Tt0, dT0)
        vb, v1, fast, vref, Fs, h, v1l, lam, iters = _runner(
            rows, cells, geo, built, T1, s0, v0, vs_presc, F, tr2, mu, mass, load, st, iters
        )
        for attempt in range(2):
            s = s0 - vb
            T1, Ta, slip, clipped, dimp, T1_in = _commit_cells(
                W, cells, geo, path, s, mu, mass, ledger
            )
            acc = (T1, Ta, slip, clipped)
            T1, Ta, slip, clipped = _commit_edges(rows, cells, geo, path, s, mu, mass, ledger, acc)
            step = (vb, fast, vref, Fs, h)
            done, vb, iters = _root_checked(
                rows, cells, dx * dt, s0, step, T1, Ta, mu, mass, st, iters
            )
            if done:
                break
            fast = False
        if mu is not None and mass is not None:
            # end velocity: the piece's exact one, plus the momentum of the force beyond it
            # (blended with backward Euler's, the mean); a massless runner's is its mean
            v1 = vb
            if mass > 0.0:
                v1 = _end_velocity(lam, v1l, vb, vref, dt, h)
        if k_sub == n_sub - 1 and mu is not None:
            stuck = _stuck_length(W, cells[0], cells[1], cells[2], cells[3], x_lo, dx, c1, a)
        xs += vb * dt  # the displacement: the integral of v* over the sub-step
        xsph += v * dt
        slip_acc += slip
        if ledger is not None:
            runner = (vb, v0, v1, lam, F)
            sums = (SIA, SIB, E0, E1, E2, SU)
            commit = (clipped, dimp, T1_in)
            imp_tick += _ledger(
                st, rows, cells, geo, c0, s0, s, runner, sums, commit, mu, mass, load
            )
        time += dt
        slip_tick += slip
    state = (c1, v1, T1, xs, xsph, time, slip_acc, iters, imp_tick, slip_tick)
    _tick_out(st, out, state, EG, a, d, stuck, mu)


@njit(**JIT)
def run_ticks(W, st, p, d, u, v, vs, mu, mass, load, n_sub, dt, out):
    """Run len(d) ticks with the energy ledger; out has shape (len(d), N_OUT).  Stops at the
    first error flag.  W must have ``work_rows(mu is not None)`` rows (the ledger writes rows
    an env's work array lacks: raises instead of writing past it)."""
    if W.shape[0] < W_L + (N_LCOL if mu is not None else 0):
        raise ValueError("run_ticks: the work array lacks the energy ledger's rows")
    for k in range(d.shape[0]):
        _tick(W, st, p, d[k], u[k], v[k], vs[k], mu, mass, load, n_sub, dt, out[k], True)
        if st[ST_FLAG] != 0.0 and (int(st[ST_FLAG]) & (FLAG_NONFINITE | FLAG_GRID)) != 0:
            return k + 1
    return d.shape[0]


@njit(**JIT)
def elastic_energy(U, st, p):
    """Tangential elastic energy 1/2 sum U_i^2 / l_i (G* = 1 units)."""
    c = st[ST_C]
    a = st[ST_A]
    x_lo = p[P_X_LO]
    dx, n = _level_grid(U.shape[0], st, p)
    if a <= 0.0:
        return 0.0
    i0, i1 = _contact_range(c, a, x_lo, dx, n)
    e = 0.0
    for i in range(i0, i1 + 1):
        xL = x_lo + i * dx
        ell = _overlap(xL, xL + dx, c, a)
        if ell > 0.0:
            e += 0.5 * U[i] * U[i] / ell
    return e


@njit(**JIT)
def normal_force_sum(st, p, n):
    """Sum over the cells of E*/G* times the exact integral of uN (normal force, G* = 1 units):
    the discrete normal force that the friction limits use."""
    c = st[ST_C]
    a = st[ST_A]
    d = st[ST_D]
    x_lo = p[P_X_LO]
    dx, n = _level_grid(n, st, p)
    if a <= 0.0:
        return 0.0
    i0, i1 = _contact_range(c, a, x_lo, dx, n)
    total = 0.0
    for i in range(i0, i1 + 1):
        xL = x_lo + i * dx
        total += _normal_content(xL, xL + dx, c, a, d, 1.0 / (3.0 * p[P_R]))
    return p[P_E_OVER_G] * total
