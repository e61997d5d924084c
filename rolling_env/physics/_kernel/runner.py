"""The runner: its exact step on a linear piece of the contact's force law, the blend into
backward Euler where its period on the contact is not resolved, the root of its equation
where a step crosses a kink of the force law (finite friction), and the tick's runner step
(``_runner``)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .cells import _cells, _clip_slope, _edge, _edges
from .layout import FLAG_NONFINITE, FLAG_SLIDE, JIT, JIT_INLINE, ST_FLAG, ST_ITER

# (omega_n dt)^2 (omega_n on the stuck contact) at which the runner step is half-way from
# the exact (piecewise) scheme to backward Euler (``_blend``)
THETA2_BLEND = 4.0


@njit(inline="always", **JIT)
def _g_eval(A, B, L, i0, i1, s0, vv, v0, mass, F, dt, st):
    """g(vv) of ``_solve_bracketed``: returns (g, T, scale, dT/ds), ``scale`` the size of the
    force terms whose round-off g carries: sum |U_i| and the slope times the round-off of
    s = s0 - vv (for ``_converged``)."""
    st[ST_ITER] += 1.0
    s = s0 - vv
    Tt = 0.0
    Ta = 0.0
    dT = 0.0
    for i in _cells(i0, i1 + 1):
        Ut, dU = _clip_slope(A[i] + B[i] * s, L[0, i], B[i])
        dT += dU
        Tt += Ut
        Ta += abs(Ut)
    return mass * (vv - v0) - dt * (Tt + F), Tt, Ta + dT * (abs(s0) + abs(vv)), dT


@njit(inline="always", **JIT)
def _converged(g, mass, vv, v0, dt, Ta, F):
    """g is piecewise linear: converged when it vanishes to round-off of its terms."""
    return abs(g) <= 1e-13 * (mass * (abs(vv) + abs(v0)) + dt * (Ta + abs(F))) + 1e-300


@njit(**JIT)
def _solve_bracketed(A, B, L, i0, i1, s0, v0, vv, mass, F, dt, st):  # noqa: C901 (safeguarded Newton: its cases are the method)
    """Safeguarded Newton/bisection for the runner velocity with finite friction.

    Root in v of g(v) = mass (v - v0) - dt (T(s0 - v) + F), T the sum of the clipped contents
    A_i + B_i s.  g is monotone and piecewise linear.  Outside the bracket where some cell
    is unsaturated every cell is saturated, T is constant and g is linear with slope
    ``mass``: a root there is taken in closed form, so a very light runner (a huge
    dt T / mass) costs no more iterations than a heavy one.  Inside, safeguarded Newton from
    ``vv``.  The fast path in ``_tick`` (one Newton step on the piece active at v0, verified
    in the commit pass) needs this only when the step crosses a kink.
    """
    s_hi = -np.inf
    s_lo = np.inf
    for i in _cells(i0, i1 + 1):
        Bi = B[i]
        if Bi > 0.0:
            sh = (L[0, i] - A[i]) / Bi
            sl = (-L[0, i] - A[i]) / Bi
            if sh > s_hi:
                s_hi = sh
            if sl < s_lo:
                s_lo = sl
    if s_hi < s_lo:  # no cell in contact: s = 0 (the limit of a vanishing contact) if massless
        s_hi = 0.0
        s_lo = 0.0
    v_lo = s0 - s_hi
    v_hi = s0 - s_lo
    # g at the bracket's ends; beyond them T is constant
    g_lo, T_lo, sc, _d = _g_eval(A, B, L, i0, i1, s0, v_lo, v0, mass, F, dt, st)
    if _converged(g_lo, mass, v_lo, v0, dt, sc, F):
        return v_lo
    if g_lo >= 0.0:
        if mass > 0.0:
            return v0 + dt * (T_lo + F) / mass
        return v_lo  # massless and every cell saturated: sliding (flagged by the caller)
    g_hi, T_hi, sc, _d = _g_eval(A, B, L, i0, i1, s0, v_hi, v0, mass, F, dt, st)
    if _converged(g_hi, mass, v_hi, v0, dt, sc, F):
        return v_hi
    if g_hi <= 0.0:
        if mass > 0.0:
            return v0 + dt * (T_hi + F) / mass
        return v_hi
    vv = min(max(vv, v_lo), v_hi)
    for _it in range(200):
        g, _t, sc, dT = _g_eval(A, B, L, i0, i1, s0, vv, v0, mass, F, dt, st)
        if _converged(g, mass, vv, v0, dt, sc, F):
            break
        if g > 0.0:
            v_hi = vv
        else:
            v_lo = vv
        if v_hi - v_lo <= 1e-15 * (abs(v_lo) + abs(v_hi)) + 1e-300:
            break
        gp = mass + dt * dT
        vn = vv - g / gp if gp > 0.0 else 0.5 * (v_lo + v_hi)
        if not (vn > v_lo and vn < v_hi):
            vn = 0.5 * (v_lo + v_hi)
        vv = vn
    return vv


@njit(**JIT)
def _solve_runner(A, B, L, i0, i1, s0, v0, vv, mass, F, dt, st):
    """The root of ``_solve_bracketed``'s g, by Newton from ``vv`` on g's pieces, bracketed by
    the points it visits (bisection once both signs are seen and a step leaves the bracket);
    where no step is possible (a massless runner with every cell saturated) or Newton does
    not settle within a few steps, ``_solve_bracketed``.  A step that crossed a kink of the
    force law usually lands on the next piece, so the root is one or two evaluations away:
    the full bracket (three passes over the cells before the first Newton step) is rarely
    needed (a light runner crosses kinks in most sub-steps)."""
    lo = -np.inf
    hi = np.inf
    for _it in range(8):
        g, _t, sc, dT = _g_eval(A, B, L, i0, i1, s0, vv, v0, mass, F, dt, st)
        if _converged(g, mass, vv, v0, dt, sc, F):
            return vv
        if g > 0.0:
            hi = vv
        else:
            lo = vv
        gp = mass + dt * dT
        if not gp > 0.0:
            break
        vn = vv - g / gp
        if not (vn > lo and vn < hi):
            if not (math.isfinite(lo) and math.isfinite(hi)):
                break
            vn = 0.5 * (lo + hi)
        if hi - lo <= 1e-15 * (abs(lo) + abs(hi)) + 1e-300 and hi - lo < np.inf:
            return vv
        vv = vn
    return _solve_bracketed(A, B, L, i0, i1, s0, v0, vv, mass, F, dt, st)


@njit(**JIT)
def _limit_sum(L, i0, i1, j0, j1):
    """Sum of the friction limits of cells i0..i1 (the inner cells j0..j1 first, then the
    edge cells, the order of the build pass)."""
    total = 0.0
    for i in _cells(j0, j1 + 1):
        total += L[0, i]
    for k in _edges(i0, i1, j0, j1):
        total += L[0, _edge(k, j0, j1)]
    return total


@njit(inline="always", **JIT)
def _phis(th2):
    """cos(th), sin(th)/th, (1 - cos(th))/th^2 and (th - sin(th))/th^3 for th^2 = th2 >= 0:
    their Taylor series below th2 = 0.3 (truncation below 3e-15; no cancellation, and about
    a third of the cost of sqrt, sin and cos, which a light runner pays every sub-step)."""
    if th2 < 0.3:
        x = th2
        c = 1.0 - x * (
            1 / 2
            - x
            * (
                1 / 24
                - x
                * (
                    1 / 720
                    - x * (1 / 40320 - x * (1 / 3628800 - x * (1 / 479001600 - x / 87178291200)))
                )
            )
        )
        p1 = 1.0 - x * (
            1 / 6
            - x
            * (
                1 / 120
                - x
                * (
                    1 / 5040
                    - x
                    * (1 / 362880 - x * (1 / 39916800 - x * (1 / 6227020800 - x / 1307674368000)))
                )
            )
        )
        p2 = 1 / 2 - x * (
            1 / 24
            - x
            * (
                1 / 720
                - x
                * (
                    1 / 40320
                    - x
                    * (
                        1 / 3628800
                        - x * (1 / 479001600 - x * (1 / 87178291200 - x / 20922789888000))
                    )
                )
            )
        )
        p3 = 1 / 6 - x * (
            1 / 120
            - x
            * (
                1 / 5040
                - x
                * (
                    1 / 362880
                    - x
                    * (
                        1 / 39916800
                        - x * (1 / 6227020800 - x * (1 / 1307674368000 - x / 355687428096000))
                    )
                )
            )
        )
        return c, p1, p2, p3
    th = math.sqrt(th2)
    sn = math.sin(th)
    hs = math.sin(0.5 * th)
    return math.cos(th), sn / th, 2.0 * hs * hs / th2, (th - sn) / (th * th2)


@njit(inline="always", **JIT)
def _blend(th2, tr2):
    """Weight of the exact runner step against backward Euler's for (omega_n dt)^2 = th2 and
    a patch travel per sub-step of sqrt(tr2) contact radii: 1 / (1 + q^4) with q = th2 /
    THETA2_BLEND + tr2; 1 - 4e-3 at omega_n dt = 1, 1/2 at 2, 4e-3 at 4.  A runner ringing at
    more than a sub-step's phase of about 2 rad is not resolved: the exact step would keep a
    ringing that the ticks sample at random (and, crossing the friction law's kinks, excite
    more); backward Euler damps it and tends to the massless runner as the mass vanishes.
    A patch that moves a contact radius or more within the sub-step renews the contact
    within it, and the exact step's contact (linear in the runner's displacement, forced by
    a ramp) no longer describes it; backward Euler's runner sees what the cells see (a
    constant velocity over the sub-step), so that its energy stays consistent with theirs.
    The blend leaves the resolved runner exact to 1 - O((omega_n dt)^8 + (u dt / a)^8)."""
    q = th2 * (1.0 / THETA2_BLEND) + tr2
    if not q < 1e60:  # also NaN: the exact step would take sin and cos of an overflow
        return 0.0
    q = q * q
    return 1.0 / (1.0 + q * q)


@njit(inline="always", **JIT)
def _blended(lam, vlin, v0, dt):
    """(vref, h) of the runner equation g(vb) = mass (vb - vref) - h (T + F - lam f1) = 0 at
    blend weight ``lam`` (``_blend``): the exact piece's mean velocity ``vlin`` and h = dt/2
    (the force beyond the piece a trapezoid) at lam = 1, backward Euler's v0 and dt at 0."""
    return lam * vlin + (1.0 - lam) * v0, (1.0 - 0.5 * lam) * dt


@njit(inline="always", **JIT)
def _end_velocity(lam, v1l, vb, vref, dt, h):
    """The runner's end velocity at blend weight ``lam``: the exact piece's ``v1l`` plus the
    momentum of the force beyond it, blended with backward Euler's (the mean velocity)."""
    return lam * (v1l + (dt / h) * (vb - vref)) + (1.0 - lam) * vb


@njit(inline="always", **JIT)
def _runner_linear(mass, k, T0, Tf1, F, v0, dt):
    """Exact sub-step of a free runner (mass > 0) on a contact whose force is linear in its
    displacement xi over the sub-step: T = T0 + (Tf1 - T0) t / dt - k xi (Tf1: the force the
    contact would reach with the runner at rest; k >= 0: the stiffness, G* times the stuck
    length), so m xi'' = T + F is an oscillator of frequency sqrt(k / m) forced by a ramp.
    Returns (mean velocity xi(dt) / dt, end velocity, end force T + F).  No numerical
    damping and no phase error for any sqrt(k / m) dt; k = 0 is a free mass."""
    th2 = k * dt * dt / mass
    c, p1, p2, p3 = _phis(th2)
    f0 = T0 + F
    dG = Tf1 - T0
    r = dt / mass
    vb = v0 * p1 + (f0 * p2 + dG * p3) * r
    v1 = v0 * c + (f0 * p1 + dG * p2) * r
    f1 = f0 * c - k * dt * p1 * v0 + dG * p1
    return vb, v1, f1


@njit(**JIT_INLINE)
def _runner_stuck(SA, SB, T1, s0, v0, F, dt, tr2, mass, load, st):
    """``_runner`` with infinite friction (the force law linear: T = SA + SB s at the end)
    for a free runner.  Returns (vb, v1, vref, h, v1l, lam)."""
    vref = v0
    h = dt
    vb = v0
    v1 = v0
    v1l = v0
    lam = 1.0
    if mass > 0.0:
        # exact; blended into backward Euler where the runner's period on the contact
        # is not resolved (``_blend``)
        lam = _blend(SB * dt / mass, tr2)
        if lam == 0.0:
            vb = (mass * v0 + dt * (SA + s0 * SB + F)) / (mass + dt * SB)
            v1 = vb
        else:
            vb, v1, f1 = _runner_linear(mass, SB / dt, T1, SA + SB * s0, F, v0, dt)
        if 0.0 < lam < 1.0:
            # the blended equation of the finite-friction step below, on a linear
            # force law (so that friction that never acts gives the same runner)
            vref, h = _blended(lam, vb, v0, dt)
            v1l = v1
            vb = (mass * vref + h * (SA + SB * s0 + F - lam * f1)) / (mass + h * SB)
            v1 = _end_velocity(lam, v1l, vb, vref, dt, h)
    elif SB > 0.0:
        vb = (SA + s0 * SB + F) / SB  # massless: T + F = 0 at the end
        v1 = vb
    else:
        # massless runner without contact: with no load any v* balances; take the
        # limit of a vanishing contact, no creep (as the finite-friction solver does).
        # A load has no equilibrium here: flag it (the wrapper raises)
        vb = s0
        v1 = vb
        if load is not None and F != 0.0:
            st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_SLIDE
    return vb, v1, vref, h, v1l, lam


@njit(**JIT_INLINE)
def _runner_sliding(rows, cells, SB, Tt0, dT0, T1, s0, v0, F, dt, dxdt, tr2, mass, st, iters):
    """``_runner`` with finite friction for a free runner: the root of the piece of the force
    law active at v0 (``_root_checked`` verifies it).  Returns (vb, fast, vref, Fs, h, v1l,
    lam, iters); fast False when the bracketed solver took the step."""
    _U, A, B, L = rows
    i0, i1, j0, j1 = cells
    fast = True
    vref = v0
    Fs = F
    h = dt
    vb = v0
    v1l = v0
    lam = 1.0
    if mass == 0.0:
        SL = _limit_sum(L, i0, i1, j0, j1)  # the largest force the contact holds
        if SL <= abs(F) and (SL > 0.0 or F != 0.0):
            st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_SLIDE
    iters += 1.0
    if mass > 0.0:
        # the piece at v0: T = Tt0 + dT0 (v0 - vb), stiffness dT0 / dt
        lam = _blend(SB * dt / mass, tr2)
        f1 = 0.0
        if lam > 0.0:
            vref, v1l, f1 = _runner_linear(mass, dT0 / dt, T1, Tt0 + dT0 * v0, F, v0, dt)
        # exact on the piece, the force beyond it a trapezoid over the sub-step (h =
        # dt / 2), where the runner's period on the stuck contact is resolved; where
        # it is not (th2 = (omega_n dt)^2 large) blended into backward Euler (vref =
        # v0, h = dt, v1 = vb), which damps the unresolved ringing that crossing the
        # force law's kinks excites instead of pumping it, and tends to the massless
        # runner as the mass vanishes (``_blend``)
        vref, h = _blended(lam, vref, v0, dt)
        Fs = F - lam * f1
        vb = vref  # the root if the step stays on that piece (the commit checks)
    else:
        h = 0.5 * dt
        g0 = -h * (Tt0 + F)
        gp = h * dT0
        if gp <= 0.0:
            # massless runner with every cell saturated (or no contact): g has no
            # slope at v0; the bracketed solver picks the root (for no contact: the
            # sphere's creep velocity, the limit of a vanishing contact)
            fast = False
            st[ST_ITER] = iters
            B[j0 : j1 + 1] = dxdt
            vb = _solve_bracketed(A, B, L, i0, i1, s0, v0, v0, mass, F, h, st)
            iters = st[ST_ITER]
        elif g0 != 0.0:
            vb = v0 - g0 / gp  # root of the linear piece active at v0
    return vb, fast, vref, Fs, h, v1l, lam, iters


@njit(**JIT_INLINE)
def _runner(rows, cells, geo, sums, T1, s0, v0, vs_presc, F, tr2, mu, mass, load, st, iters):
    """The tick's runner step.  vb: the runner's mean velocity over the sub-step (its
    displacement / dt), which the cells' creep takes (s = s0 - vb); v1: its velocity at the
    end.  A free runner (mass > 0) on the piece of the contact's force law active at v0 is a
    linear oscillator forced by a ramp, propagated exactly (``_runner_linear``); with
    friction a step that crosses a kink of the force law solves g(vb) = mass (vb - vref) -
    h (T(s0 - vb) + Fs) = 0 (monotone), exact on the piece and a trapezoid in the force
    beyond it (``_solve_runner`` with h = dt/2, in ``_root_checked``).  ``sums``: (SA,
    SB, Tt0, dT0) of the build pass.  Returns (vb, v1, fast, vref, Fs, h, v1l, lam, iters):
    the equation the commit verifies (fast: by one evaluation), the exact piece's end
    velocity v1l and the blend weight lam."""
    SA, SB, Tt0, dT0 = sums
    dt = geo[8]
    fast = True
    vref = v0
    Fs = F
    h = dt
    vb = v0
    v1 = v0
    v1l = v0
    lam = 1.0
    if mass is None:
        vb = vs_presc
        v1 = vs_presc
    elif mu is None:
        vb, v1, vref, h, v1l, lam = _runner_stuck(SA, SB, T1, s0, v0, F, dt, tr2, mass, load, st)
    else:
        vb, fast, vref, Fs, h, v1l, lam, iters = _runner_sliding(
            rows, cells, SB, Tt0, dT0, T1, s0, v0, F, dt, geo[9], tr2, mass, st, iters
        )
    if not abs(dt * SB) < np.inf:
        # the contact's stiffness times the step overflows: the runner step cannot be
        # formed (it would take a finite force for none); reported as non-finite
        st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_NONFINITE
    return vb, v1, fast, vref, Fs, h, v1l, lam, iters
