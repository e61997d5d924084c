"""The kernel's two code paths for one physics: the env's (no energy ledger, closed-form edge
cells, ``_kernel._walk_content``) and ``Drive.run``'s (ledger on, ``_kernel._walk``) must give
the same trajectories to round-off, and both the trajectories of the kernel before the
2026-11-24 speed-ups (a recorded reference); the observation clock table of the env kernel."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit

import rolling_env
from rolling_env.env import _envkernel as EK
from rolling_env.env.vector import BatchCore
from rolling_env.physics import _kernel as K

sys.path.insert(0, str(Path(__file__).parent.parent))  # tests/make_golden.py


def _random_cells(rng, n):
    """Cells of width dx at x_lo + i dx, contacts wider and narrower than a cell, centres
    before, on and past the cell, speeds of both signs down to 1e-305 (1/|u| overflows)."""
    dx = 10.0 ** rng.uniform(-2, 1, n)
    xL = rng.uniform(-3, 3, n)
    a = dx * 10.0 ** rng.uniform(-0.5, 1.5, n)  # about 10% narrower than a cell
    c0 = xL + rng.uniform(-2, 2, n) * (a + dx)
    u = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-3, 1, n)
    u[::17] = 0.0
    u[5::23] = rng.choice([-1.0, 1.0]) * 1e-305
    dt = 10.0 ** rng.uniform(-2, 0.5, n)
    dt[5::23] = 1e303  # moves the 1e-305 speeds by about a cell
    U0 = rng.normal(size=n) * dx
    return dx, xL, a, c0, u, dt, U0


def test_closed_form_edge_cell_matches_the_walk():
    """(A, B) of ``_walk_content`` equal those of ``_walk`` to 1e-12 of the content scale,
    over 20,000 random cells (entry, full, exit, passing through, narrow contacts,
    both directions, u = 0 and |u| so small that 1/|u| overflows)."""
    rng = np.random.default_rng(7)
    dx, xL, a, c0, u, dt, U0 = _random_cells(rng, 20_000)
    for k in range(dx.size):
        inv = K._inv_speed(u[k])
        args = (U0[k], xL[k], xL[k] + dx[k], c0[k], a[k], u[k], inv, dt[k])
        A1, B1 = K._walk_content(*args)
        A2, B2 = K._walk(*args)[:2]
        scale_A = abs(U0[k]) + 1e-300
        scale_B = dx[k] * dt[k]
        err = max(abs(A1 - A2) / scale_A, abs(B1 - B2) / scale_B)
        assert err <= 1e-12, (
            f"cell {k}: closed form ({A1!r}, {B1!r}) vs walk ({A2!r}, {B2!r}); inputs {args}"
        )


def _boundary_cells(rng, n):
    """Cells and motions whose start and end land exactly on the piece boundaries of the walk
    (contact edge at a cell edge, at a cell midpoint, contact exactly two cells wide...):
    power-of-two coordinates and |u| = 1, so every sum is exact."""
    cases = []
    for _ in range(n):
        dx = 2.0 ** rng.integers(-6, 3)
        pL = rng.integers(-64, 64) * 2.0**-6
        pR = pL + dx
        a = [dx / 2, dx * 2.0 ** rng.integers(-3, 6), dx * rng.uniform(0.5, 8)][rng.integers(3)]
        b = [pL - a, min(pR - a, pL + a), max(pR - a, pL + a), pR + a]
        pts = b + [
            pL,
            pR,
            pL - 2 * a - dx,
            pR + 2 * a + dx,
            0.5 * (b[0] + b[1]),
            0.5 * (b[2] + b[3]),
            0.5 * (b[1] + b[2]),
        ]
        p, pe = sorted((pts[rng.integers(len(pts))], pts[rng.integers(len(pts))]))
        if pe == p:
            pe = p + dx * rng.uniform(0, 3)
        U0 = rng.normal() * dx
        cases.append((U0, pL, pR, p, a, 1.0, pe - p))
        cases.append((U0, -pR, -pL, -p, a, -1.0, pe - p))  # the same, moving to -x
    return cases


def test_closed_form_edge_cell_matches_the_walk_on_piece_boundaries():
    """Starts and ends exactly on the entry / full / exit boundaries (4,000 cases, both
    directions): the closed form and the walk agree to 1e-12 and are finite together."""
    for U0, xL, xR, c0, a, u, dt in _boundary_cells(np.random.default_rng(11), 2000):
        inv = K._inv_speed(u)
        A1, B1 = K._walk_content(U0, xL, xR, c0, a, u, inv, dt)
        A2, B2 = K._walk(U0, xL, xR, c0, a, u, inv, dt)[:2]
        assert np.isfinite([A1, B1, A2, B2]).all(), (U0, xL, xR, c0, a, u, dt, A1, B1, A2, B2)
        err = max(abs(A1 - A2) / (abs(U0) + 1e-300), abs(B1 - B2) / ((xR - xL) * dt))
        assert err <= 1e-12, (
            f"closed form ({A1!r}, {B1!r}) vs walk ({A2!r}, {B2!r}) at {(U0, xL, xR, c0, a, u, dt)}"
        )


def test_edge_limit_is_the_friction_limit_and_its_value_per_unit_overlap():
    """``_edge_limit`` (the edge cells' friction limit and the limit per unit overlap the
    commit's slip work takes, instead of a division by the overlap) against the limit from
    ``_normal_content``: to 1e-13 of it; the limit per unit overlap times the overlap is the
    limit; (0, 0) for a cell out of contact, and a cell whose part in contact has uN < 0
    nowhere (uN >= 0 inside the contact by construction, so only round-off could)."""
    rng = np.random.default_rng(11)
    dx, xL, a, c, _u, _dt, _U0 = _random_cells(rng, 4000)
    R = 10.0 ** rng.uniform(0, 3, dx.size)
    d = a * a / R
    muEG = 10.0 ** rng.uniform(-2, 2, dx.size)
    n_in = 0
    for k in range(dx.size):
        inv3R = 1.0 / (3.0 * R[k])
        xR = xL[k] + dx[k]
        Li, q = K._edge_limit(xL[k], xR, c[k], a[k], d[k], inv3R, muEG[k])
        ell = K._overlap(xL[k], xR, c[k], a[k])
        want = muEG[k] * K._normal_content(xL[k], xR, c[k], a[k], d[k], inv3R)
        if ell == 0.0:
            assert (Li, q) == (0.0, 0.0), f"cell {k} out of contact: limit {Li}, q {q}"
            continue
        n_in += 1
        assert q >= 0.0 and Li >= 0.0, f"cell {k}: negative limit {Li} or q {q}"
        assert Li == pytest.approx(want, rel=1e-13, abs=1e-13 * muEG[k] * d[k] * ell), (
            f"cell {k}: limit {Li}, from the normal content {want}"
        )
        assert q * ell == pytest.approx(Li, rel=1e-15, abs=1e-300), (
            f"cell {k}: q * overlap = {q * ell}, limit {Li}"
        )
    assert n_in > 1000, f"only {n_in} of the random cells touch their contact"


def test_closed_form_edge_cell_below_the_rounding_step_stays_finite():
    """A cell narrower than the rounding step of its coordinates (x + a gives the same float at
    both cell edges) leaves the contact with nothing, as in the walk, not with 0/0 = NaN."""
    args = (0.5, 0.0, 1.0, 2.0**60 - 1024, 2.0**60, 1.0, 1.0, 2048.0)
    assert K._walk_content(*args) == (0.0, 0.0) == K._walk(*args)[:2]


DRIFT = (0.05, 0.01)  # the inner cells' start limits: end limit - (0.05 + 0.01 i)


def _commit_reference(W, i0, i1, j0, j1, dxdt, s, inv_dx, mass):
    """Plain-Python commit of cells i0..i1 (finite friction): inner cells j0..j1 with B = dx dt
    and overlap dx, edge cells with the build pass's B and limit per unit overlap q; a content
    beyond its limit slides to it (slip work (|U| - L) q, none for a cell out of contact; q:
    an inner cell's mean of its limit over dx from the time its content meets it, the start
    limit being its end limit less ``DRIFT``)."""
    W = W.copy()
    T1 = Ta = slip = 0.0
    for i in range(i0, i1 + 1):
        inner = j0 <= i <= j1
        Bi = dxdt if inner else W[K.W_B, i]
        Li = W[K.W_L + K.L_LIMIT, i]
        Ut = W[K.W_A, i] + Bi * s
        q = W[K.W_L + K.L_QLIM, i]
        if inner:
            dL = DRIFT[0] + DRIFT[1] * i
            a0 = math.copysign(1.0, Ut) * W[K.W_A, i]  # start content on the side it ends
            tau = 0.0
            if abs(Ut) > Li and a0 < Li - dL:  # starts inside: slides once it meets the limit
                tau = (Li - dL - a0) / ((abs(Ut) - Li) - (a0 - (Li - dL)))
            q = (Li - 0.5 * dL * (1.0 - tau)) * inv_dx
        if abs(Ut) > Li:
            slip += (abs(Ut) - Li) * q
            Ut = math.copysign(Li, Ut)
        W[K.W_U, i] = Ut
        T1 += Ut
        Ta += abs(Ut) if mass is not None else 0.0
    return W, (T1, Ta, slip)


@pytest.mark.parametrize("mass", [None, 0.0, 2.5])
@pytest.mark.parametrize(
    "i0, i1, j0, j1",
    [
        (0, 11, 3, 8),  # edge cells on both sides, the contact at the row's first and last cell
        (0, 11, 0, 11),  # inner cells only
        (2, 9, 10, 9),  # no inner cell (j0 = i1 + 1): every cell an edge cell
        (5, 5, 6, 5),  # a single edge cell
        (0, -1, 0, -1),  # no cell (lift-off, or the contact off the row): nothing committed
    ],
)
def test_commit_of_every_cell_matches_a_plain_reference(i0, i1, j0, j1, mass):
    """``_commit`` with ``edges=True`` (the env's one loop over inner and edge cells) against a
    plain per-cell loop: contents exactly equal (the per-cell arithmetic is not reordered),
    sums to 1e-13 (reassoc reorders them), cells outside i0..i1 untouched, clipping on both
    signs and an edge cell out of contact (overlap 0: clipped to 0 with no slip work)."""
    rng = np.random.default_rng(7)
    n = 12
    W = rng.normal(size=(K.work_rows(True), n))
    W[K.W_L + K.L_LIMIT] = rng.uniform(0.0, 1.0, n)
    W[K.W_L + K.L_QLIM] = W[K.W_L + K.L_LIMIT] * rng.uniform(0.5, 4.0, n)  # 1 / overlap
    W[K.W_L + K.L_LIMIT, 1] = 0.0  # an edge cell that left the contact
    W[K.W_L + K.L_QLIM, 1] = 0.0
    W[K.W_A, 1] = 0.3
    W[K.W_A, 5] = -3.0  # with B = 0.5: A + B s = -2.15, beyond its limit (<= 1): slides
    W[K.W_B, 5] = 0.5
    W[K.W_A, 7] = 3.0  # inner (B = 0.4) or edge (B = 0.5): beyond its limit, positive side
    W[K.W_B, 7] = 0.5
    dxdt, s, inv_dx = 0.4, 1.7, 2.0
    want_W, want = _commit_reference(W, i0, i1, j0, j1, dxdt, s, inv_dx, mass)
    got = K._commit(W, i0, i1, j0, j1, dxdt, s, inv_dx, 0.2, mass, True, None, DRIFT)
    np.testing.assert_array_equal(
        W[K.W_U], want_W[K.W_U], err_msg="committed contents differ from the plain loop"
    )
    np.testing.assert_array_equal(W[1:], want_W[1:], err_msg="commit changed a row it only reads")
    assert got[3:] == (0, 0, 0.0), f"census counts {got[3:]} without a census"
    for name, g, w in zip(("T1", "Ta", "slip"), got[:3], want):
        assert g == pytest.approx(w, rel=1e-13, abs=1e-300), f"{name} = {g}, plain loop {w}"
    U, L = want_W[K.W_U, i0 : i1 + 1], want_W[K.W_L + K.L_LIMIT, i0 : i1 + 1]
    n_pos = int(np.sum((U == L) & (L > 0)))  # slid to +limit
    n_neg = int(np.sum((U == -L) & (L > 0)))  # slid to -limit
    if i1 >= i0:  # the case must exercise the slip path (else it could pass with it broken)
        assert n_pos + n_neg > 0, "no cell of the case slid to its limit"
    if i0 <= 5 <= i1 and i0 <= 7 <= i1:
        assert n_pos > 0 and n_neg > 0, f"slid: {n_pos} positive, {n_neg} negative"


@pytest.mark.parametrize(
    "a, b, L0, L1",
    [
        (0.2, 0.9, 0.5, 0.3),  # starts stuck, meets its falling limit a third into the sub-step
        (-0.5, 0.9, 0.5, 0.3),  # starts at the other limit (creep reversal)
        (0.5, 0.9, 0.5, 0.3),  # at its limit throughout: the trapezoid of the limit
        (-0.1, -0.8, 0.2, 0.6),  # negative side, rising limit
    ],
)
def test_inner_cell_slip_work_is_the_exact_integral_over_its_sliding_part(a, b, L0, L1):
    """An inner cell whose content moves straight from a to b (unclipped) over a sub-step while
    its limit goes straight from L0 to L1 slides from the moment the content meets the limit;
    its slip work is the integral of the limit times the slid distance: against the continuum
    cell integrated in 2e5 time steps, to 1e-4 relative (the commit charges the mean limit of
    the sliding part; the mean over the whole sub-step is 9-19% off in three of these cases)."""
    n, inv_dx = 3, 2.0
    W = np.zeros((K.work_rows(True), n))
    W[K.W_A, 1] = a
    W[K.W_L + K.L_LIMIT, 1] = L1
    drift = np.array([L1 - L0, 0.0])  # the limit's change over the sub-step, alpha + beta i
    dxdt, s = 1.0, b - a  # A + B s = b
    _, _, slip, _, _, _ = K._commit(W, 1, 1, 1, 1, dxdt, s, inv_dx, 0.2, None, True, None, drift)
    m = 200_000
    lim = L0 + (L1 - L0) * (np.arange(1, m + 1) / m)
    u, work = a, 0.0
    for k in range(m):  # the continuum cell: follows the creep, held at +-lim
        step = (b - a) / m
        v = u + step
        c = min(max(v, -lim[k]), lim[k])
        work += abs(v - c) * lim[k] * inv_dx
        u = c
    assert slip == pytest.approx(work, rel=1e-4), f"slip work {slip}, continuum {work}"


@pytest.mark.parametrize("edges", [True, None])
@pytest.mark.parametrize("where", [0, 5, 10])  # first cell, middle, last (scalar remainder)
def test_commit_keeps_a_nan_content(edges, where):
    """A NaN content (a blown-up cell) stays NaN through the clip to the friction limit and
    reaches T1, so that the tick's non-finite check sees it: the clip's min/max must not
    replace it with a limit.  Cells 0..10, with the inner cells 3..8 (edges) or all of them
    inner: LLVM's loops take 11 cells as two 4-wide vectors and a scalar remainder of 3, so
    cells 0 and 5 go through the vector code and cell 10 through the scalar one."""
    n = 11
    W = np.zeros((K.work_rows(True), n))
    W[K.W_L + K.L_LIMIT] = 1.0
    W[K.W_L + K.L_QLIM] = 1.0
    W[K.W_B] = 0.5
    W[K.W_A] = 2.0  # every other cell beyond its limit: the clip is exercised
    W[K.W_A, where] = np.nan
    j0, j1 = (3, 8) if edges else (0, n - 1)
    T1, Ta, _slip, _ns, _nk, _nh = K._commit(
        W, 0, n - 1, j0, j1, 0.4, 0.3, 2.0, 0.2, 1.0, edges, None, DRIFT
    )
    assert math.isnan(W[K.W_U, where]), f"cell {where} committed {W[K.W_U, where]}, not NaN"
    assert math.isnan(T1) and math.isnan(Ta), f"T1 = {T1}, Ta = {Ta}: the NaN was lost"
    others = np.delete(W[K.W_U], where)
    np.testing.assert_array_equal(others, 1.0, err_msg="the other cells not clipped to +1")


@pytest.mark.parametrize(
    "a,b,L0,L1",
    [
        (0.9, -5.0, 1.0, 0.8),  # a creep reversal: from +limit across to -limit early on
        (1.0, 3.0, 1.0, 0.6),  # sliding at a falling limit all through
        (0.2, 0.5, 1.0, 1.2),  # inside all through (no clip)
        (-0.5, 4.0, 0.7, 0.7),  # constant limit, stuck then sliding
        (2.0, 2.0, 1.0, 0.5),  # no motion, beyond both limits (clip at the limit)
        (-3.0, 0.1, 1.0, 0.0),  # to a limit of 0 (leaving the contact)
        (0.0, 1e-300, 0.0, 0.0),  # out of contact
    ],
)
def test_clip_path_is_the_exact_mean_of_the_clipped_straight_path(a, b, L0, L1):
    """``_clip_path`` (the ledger's impulse of a cell that slid) against a fine midpoint sum of
    clip(a + (b - a) t, -L(t), L(t)) with L linear from L0 to L1 (2e5 points: its error is
    below 1e-9 of the scale): 1e-9 of max(|a|, |b|, L0, L1)."""
    t = (np.arange(200_000) + 0.5) / 200_000
    lim = L0 + (L1 - L0) * t
    want = np.mean(np.clip(a + (b - a) * t, -lim, lim))
    got = K._clip_path(a, b, L0, L1)
    scale = max(abs(a), abs(b), L0, L1, 1e-300)
    assert abs(got - want) <= 1e-9 * scale, f"clip path mean {got}, quadrature {want}"


def test_commit_census_counts_the_cells_that_slid_and_those_whose_path_bends():
    """The ledger's census in the inner cells' commit (``_commit`` with ``census``): the cells
    that slid, of those the ones that did not start at their limit on the side they end on (a
    creep reversal, or a stuck cell that starts to slide), and the signed count (+1 at +L,
    -1 at -L) of those that slid, against a plain count; the commit itself is the one
    without the census.  ``_impulse_fix`` returns the signed count of the bent ones, so that
    the difference counts the cells held at their limit.  Start limit = end limit - (alpha +
    beta i);
    here alpha = 0.05, beta = 0.01."""
    n = 12
    W = np.zeros((K.work_rows(True), n))
    L1 = np.linspace(1.0, 1.4, n)
    W[K.W_L + K.L_LIMIT] = L1
    L0 = L1 - (0.05 + 0.01 * np.arange(n))
    # starts: at the start limit (stays there), inside (starts to slide), at the other limit
    # (reversal), and cells that end inside (no slide)
    W[K.W_A] = [
        L0[0],
        -L0[1],
        0.2,
        L0[3],
        -0.3,
        L0[5],
        0.5 * L0[6],
        -L0[7],
        L0[8],
        0.0,
        L0[10],
        -L0[11],
    ]
    dxdt, s = 0.4, np.array([3.0, -3.0, 3.0, -6.0, -4.0, 0.1, 2.0, -1.0, 5.0, 0.5, -8.0, 2.0])
    b = W[K.W_A] + dxdt * s  # unclipped ends (the kernel takes one creep s per call)
    slid = np.abs(b) > L1
    bends = slid & ~((W[K.W_A] * b > 0) & (np.abs(W[K.W_A]) >= L0 * (1 - 1e-9)))
    held = np.where(slid & ~bends, np.sign(b), 0.0)
    assert slid.sum() >= 6 and bends.sum() >= 3 and (held > 0).any() and (held < 0).any(), (
        slid,
        bends,
        held,
    )
    # several cells in one call (one creep): every cell of both signs, the packed count
    Wn = W.copy()
    got = K._commit(Wn, 0, n - 1, 0, n - 1, dxdt, 3.0, 2.0, 0.2, None, None, True, DRIFT)
    bn = W[K.W_A] + dxdt * 3.0
    sl = np.abs(bn) > L1
    assert got[3] == sl.sum() and got[5] == np.sign(bn[sl]).sum(), (got[3:], sl)
    for i in range(n):  # one cell at a time, each with its own creep s
        Wi = W.copy()
        got = K._commit(Wi, i, i, i, i, dxdt, s[i], 2.0, 0.2, None, None, True, DRIFT)
        Wr = W.copy()
        plain = K._commit(Wr, i, i, i, i, dxdt, s[i], 2.0, 0.2, None, None, None, DRIFT)
        assert got[:3] == plain[:3], f"cell {i}: the census changed the commit"
        np.testing.assert_array_equal(Wi, Wr, err_msg=f"cell {i}: the census changed a row")
        want = (int(slid[i]), int(bends[i]), float(np.sign(b[i])) if slid[i] else 0.0)
        assert got[3:] == want, f"cell {i}: census {got[3:]}, plain count {want}"
    # _impulse_fix's signed count of the bent cells (its start limits from the geometry: here
    # the end limits, patch centre fixed), against a plain count
    x_lo, dx, c0, muEG, d, inv3R = -6.0, 1.0, 0.0, 0.1, 40.0, 0.01
    Wf = np.zeros((K.work_rows(True), n))
    Lg = np.array([K._inner_limit(x_lo, dx, i, c0, muEG, d, inv3R) for i in range(n)])
    Wf[K.W_L + K.L_LIMIT] = Lg
    Wf[K.W_A] = Lg * np.array([1, -1, 0.2, -0.3, 1, -1, 0.5, -0.5, 1, 0.9, -1, 0.0])
    for sc in (20.0, -20.0):
        bf = Wf[K.W_A] + dxdt * sc
        kinks = (np.abs(bf) > Lg) & ~((Wf[K.W_A] * bf > 0) & (np.abs(Wf[K.W_A]) >= Lg * (1 - 1e-9)))
        _fix, n_bent = K._impulse_fix(Wf, 0, n - 1, x_lo, dx, c0, muEG, d, inv3R, dxdt, sc)
        assert kinks.sum() >= 4 and n_bent == np.sign(bf[kinks]).sum(), (sc, n_bent, kinks)


def test_ledger_impulse_is_accurate_at_creep_reversals():
    """With finite friction the impulse of a sub-step in which cells slide was a trapezoid on
    T: first order where the creep reverses (T flips from +mu N to -mu N early in the first
    sub-step), 1.7% of the largest per-tick impulse at 40 sub-steps per tick and an energy
    residual of -1.6% of the drive work (energy created).  Each inner cell that slides now adds
    its clipped path's integral less its trapezoid (``_impulse_fix``).  24 random ticks (mu
    0.02, prescribed runner, v = u x U(-1, 2): creep reversals), 40 against 4000 sub-steps per
    tick: per-tick impulse within 1e-4 of the largest (measured 1.1e-6), end-of-tick T equal
    to 1e-12 (unaffected), and the residual / drive work in [0, 1e-3] at 40 sub-steps
    (measured +7.9e-5: dissipated, not created)."""
    from rolling_env.physics.model import Drive, DriveParams

    R, E, a1, tau = 1e-3, 115e9, 2e-5, 1e-3
    rng = np.random.default_rng(11)
    k = 24
    d = a1**2 / R * rng.uniform(0.2, 1.0, k)
    u = (5 * a1 / tau) * rng.choice([-1.0, 1.0], k) * rng.uniform(0.3, 1.0, k)
    d[[5, 13]] = 0.0  # lift-offs
    u[[8, 17]] = 0.0
    v = u * rng.uniform(-1.0, 2.0, k)
    vs = 0.003 * np.abs(u)
    dt = tau / 8
    reach = np.abs(u).sum() * dt
    assert np.any(np.diff(np.sign(u - v - vs)) != 0), "no creep reversal in the case"

    def run(n_sub):
        drv = Drive(
            DriveParams(R, E, 0.8235 * E, mu=0.02),
            a_ref=a1,
            resolution=64,
            stroke=(-reach, reach),
            a_max=a1,
            t_ref=tau,
        )
        drv.reset()
        out = drv.run(dt_tick=dt, n_sub=n_sub, omega_R=u, v=v, d=d, vstar=vs)
        return out, drv.energy

    (coarse, e), (fine, _) = run(40), run(4000)
    scale = np.max(np.abs(fine["impulse"]))
    err = np.max(np.abs(coarse["impulse"] - fine["impulse"])) / scale
    assert err < 1e-4, f"per-tick impulse off by {err:.2e} of the largest at 40 sub-steps"
    np.testing.assert_allclose(
        coarse["T"],
        fine["T"],
        rtol=0,
        atol=1e-12 * np.max(np.abs(fine["T"])),
        err_msg="T itself changed",
    )
    res = e["residual"] / e["drive"]
    assert 0.0 <= res < 1e-3, f"energy residual / drive work {res:.2e} at 40 sub-steps"


@pytest.mark.parametrize("mu,bounds", [(0.2, (1e-4, 1e-5)), (1.0, (5e-4, 1e-4))])
def test_ledger_impulse_in_steady_partial_slip(mu, bounds):
    """Steady rolling with a slip zone at the trailing edge (v = 0.999 omega R, prescribed
    runner at rest, 64 cells per a1), per-tick impulse against 4096 sub-steps per tick: within
    1e-4 / 1e-5 of the largest at 16 / 64 sub-steps for mu 0.2 (measured 1.5e-5 / 1.9e-6),
    5e-4 / 1e-4 for mu 1 (1.1e-4 / 2.2e-5), and falling at least 4x from 16 to 64.  Each edge
    cell takes its own integral (``_edge_impulse``: exact where it sticks or slides all through) and
    the inner cells at their limit the curvature term: with the inner cells corrected alone
    this measured 6.9e-4 / 4.3e-5 and 2.6e-3 / 1.9e-4, the trapezoid on T alone
    8.3e-5 / 6.1e-6 and 6.9e-5 / 4.0e-6 (docs/physics.md, "Impulse and work with finite
    friction")."""
    from rolling_env.physics.model import Drive, DriveParams

    R, E, a1, tau = 1e-3, 115e9, 2e-5, 1e-3
    k, u, dt = 6, 5 * a1 / tau, tau / 8
    reach = 1.1 * u * dt * k

    def impulse(n_sub):
        drv = Drive(
            DriveParams(R, E, 0.8235 * E, mu=mu),
            a_ref=a1,
            resolution=64,
            stroke=(-reach, reach),
            a_max=a1,
            t_ref=tau,
        )
        drv.reset()
        return drv.run(
            dt_tick=dt,
            n_sub=n_sub,
            omega_R=np.full(k, u),
            v=np.full(k, 0.999 * u),
            d=np.full(k, a1**2 / R),
            vstar=np.zeros(k),
        )["impulse"]

    ref = impulse(4096)
    err = {n: np.max(np.abs(impulse(n) - ref)) / np.max(np.abs(ref)) for n in (16, 64)}
    assert err[16] < bounds[0] and err[64] < bounds[1], f"mu {mu}: per-tick impulse errors {err}"
    assert err[16] > 4 * err[64], f"mu {mu}: not converging: {err}"


def test_ledger_impulse_in_steady_full_sliding_is_exact():
    """Rolling with the whole contact sliding (v = 0.9 omega R, mu 0.2, prescribed runner at
    rest): T = mu N all through, so every tick after the first (the start from rest) has the
    impulse mu N dt_tick, to 1e-12 of it at only 8 sub-steps per tick (measured 5e-14): the
    edge cells slide all through and take their limit's exact integral, the inner cells the
    trapezoid with the curvature term (without it this fails; the trapezoid on T alone,
    before the per-cell ledger, was exact here too, T being constant)."""
    from rolling_env.physics.model import Drive, DriveParams

    R, E, a1, tau, mu = 1e-3, 115e9, 2e-5, 1e-3, 0.2
    k, u, dt = 6, 5 * a1 / tau, tau / 8
    reach = 1.1 * u * dt * k
    drv = Drive(
        DriveParams(R, E, 0.8235 * E, mu=mu),
        a_ref=a1,
        resolution=64,
        stroke=(-reach, reach),
        a_max=a1,
        t_ref=tau,
    )
    drv.reset()
    out = drv.run(
        dt_tick=dt,
        n_sub=8,
        omega_R=np.full(k, u),
        v=np.full(k, 0.9 * u),
        d=np.full(k, a1**2 / R),
        vstar=np.zeros(k),
    )
    muN = mu * out["N"][-1]
    assert np.allclose(np.abs(out["T"][1:]), muN, rtol=1e-9, atol=0), "not fully sliding"
    err = np.max(np.abs(np.abs(out["impulse"][1:]) - muN * dt)) / (muN * dt)
    assert err < 1e-12, f"impulse off by {err:.1e} of mu N dt in steady full sliding"


@pytest.mark.parametrize(
    "xL,xR,c0,h",
    [
        (-0.3, -0.2, 0.0, 0.05),  # inside the contact all through
        (0.9, 1.0, 0.0, 0.06),  # entering: the leading edge (c + a) crosses the cell
        (-1.05, -0.95, 0.0, 0.08),  # leaving at the trailing edge
        (-1.02, -0.98, 0.0, -0.07),  # rolling backwards over the edge
        (-0.5, 2.0, 0.0, 0.3),  # a cell wider than the contact's half-width
        (1.5, 1.6, 0.0, 0.1),  # never in contact
        (0.95, 1.05, 0.0, 3e-7),  # a patch that hardly moves (the midpoint rule)
    ],
)
def test_limit_integral_is_exact(xL, xR, c0, h):
    """``_limit_integral`` (the time integral of a cell's friction limit while the patch moves
    by h in a sub-step) against a fine midpoint sum of ``_edge_limit``: within 1e-9 of the
    largest limit times the sub-step."""
    a, R, muEG, dt = 1.0, 2.5, 0.3, 0.5
    d = a * a / R
    u = h / dt
    got = K._limit_integral(xL, xR, c0, u, dt, a, d, 1 / (3 * R), muEG)
    m = 20_000  # midpoints: error ~ (h / m)^2 where the limit is smooth, h / m^2 at a kink
    t = (np.arange(m) + 0.5) * dt / m
    want = sum(K._edge_limit(xL, xR, c0 + u * tk, a, d, 1 / (3 * R), muEG)[0] for tk in t)
    want *= dt / m
    scale = muEG * (xR - xL) * d * dt
    assert abs(got - want) <= 1e-9 * scale, f"limit integral {got}, quadrature {want}"


def test_kernels_compile_without_reference_counting():
    """With the numba this project is tested against, the kernels are built without numba's
    reference counting (``_nrt=False``: 5% of the serial kernel, +12% for the threaded
    batch); a numba without the option keeps them working, but slower."""
    assert K.JIT.get("_nrt") is False, f"kernel options {K.JIT}: reference counting is on"
    assert K.JIT["error_model"] == "numpy"


def test_only_the_ticks_steps_are_inlined_by_llvm():
    """The tick's steps are marked for LLVM to inline (``K.JIT_INLINE``); every other kernel
    of the physics sets ``forceinline=False`` itself, since numba would otherwise hand a
    step's ``forceinline`` down to the kernels it calls (the vectorised cell loops are
    1.1-1.2x slower inlined into the tick: docs/performance-log.md)."""
    kernels = {
        f"{m.__name__}.{n}": v
        for m in K.MODULES
        for n, v in vars(m).items()
        if hasattr(v, "py_func") and v.py_func.__module__ == m.__name__
    }
    unset = sorted(n for n, d in kernels.items() if "forceinline" not in d.targetoptions)
    assert not unset, f"kernels that leave forceinline to their caller: {unset}"
    steps = {n.rsplit(".", 1)[1] for n, d in kernels.items() if d.targetoptions["forceinline"]}
    assert {"_build", "_runner", "_commit_cells", "_commit_edges", "_ledger"} <= steps, steps
    assert not steps & {"_tick", "_build_inner", "_commit", "_solve_runner", "_set_radius"}


@njit
def _run(W, st, p, d, u, v, mu, mass, load, n_sub, dt, outs, ledger):
    for k in range(d.shape[0]):
        K._tick(W, st, p, d[k], u[k], v[k], 0.0, mu, mass, load, n_sub, dt, outs[k], ledger)


def _inputs(core, ticks, seed):
    """Scaled (d, u, v) per tick as the env kernel makes them from random actions; the
    rolling rate goes back and forth (pairs of ticks of opposite rates) so that the contact
    stays on the spring row."""
    sv = core.sv
    act = np.random.default_rng(seed).uniform(-1, 1, (ticks, 3))
    N = sv[EK.S_N_MIN] + 0.5 * (act[:, 0] + 1) * (sv[EK.S_N_MAX] - sv[EK.S_N_MIN])
    L0, t0 = sv[EK.S_L0], sv[EK.S_T0]
    d = (3 * N / (4 * sv[EK.S_E] * math.sqrt(sv[EK.S_R]))) ** (2 / 3) / L0
    u = np.abs(act[:, 1]) * sv[EK.S_UMAX] * t0 / L0
    u[1::2] = -u[0::2][: u[1::2].size]
    v = u * (1 - act[:, 2] * sv[EK.S_CREEP])
    n_sub = int(sv[EK.S_NSUB])
    return d, u, v, n_sub, sv[EK.S_DT] / n_sub / t0


@pytest.mark.parametrize("scene", rolling_env.list_scenes())
def test_env_path_matches_the_ledger_path(scene):
    """The env kernel leaves the energy ledger out and integrates the edge cells in closed
    form; ``Drive.run`` keeps the ledger and walks them.  Over 300 random ticks of every
    shipped scene (its own friction, mass and load) T, v*, x*, slip work and contact centre
    agree to 1e-11 of each column's largest value, and the stuck fraction to one cell in a
    hundred ticks (a cell exactly at its friction limit may read either way)."""
    core = BatchCore(1, scene=scene)
    d, u, v, n_sub, dt = _inputs(core, 300, seed=3)
    mu, mass, load, _ = core.features
    outs = {}
    for ledger in (True, None):
        W = np.zeros((K.work_rows(mu is not None, ledger is not None), core.cells.shape[2]))
        W[: core.cells.shape[1]] = core.cells[0, : W.shape[0]]  # the env's rows lack the ledger's
        st = core.st[0].copy()
        out = np.zeros((d.size, K.N_OUT))
        _run(W, st, core.p[0], d, u, v, mu, mass, load, n_sub, dt, out, ledger)
        assert st[K.ST_FLAG] == 0, f"{scene}: flags {st[K.ST_FLAG]} (contact left the row?)"
        outs[ledger] = out
    ref, env = outs[True], outs[None]
    for col, name in [
        (K.OUT_T, "T"),
        (K.OUT_VS, "v*"),
        (K.OUT_XS, "x*"),
        (K.OUT_SLIP, "slip work"),
        (K.OUT_C, "c"),
        (K.OUT_N, "N"),
    ]:
        scale = np.abs(ref[:, col]).max() + 1e-300
        err = np.abs(env[:, col] - ref[:, col]).max() / scale
        assert err <= 1e-11, f"{scene}: {name} differs by {err:.1e} of its largest value"
    stick = np.abs(env[:, K.OUT_STICK] - ref[:, K.OUT_STICK])
    assert stick.max() <= 0.2 and stick.mean() <= 1e-3, (
        f"{scene}: stuck fraction differs by up to {stick.max():.3f}, mean {stick.mean():.1e}"
    )


@pytest.mark.parametrize("mu", [0.3, None])
def test_load_drop_without_the_ledger_leaves_only_the_ledger_out(mu):
    """``_set_radius`` without the ledger (the env) gives the same contents, T and slip work
    as with it, bit for bit, and leaves out only the ledger's energies (release and snap),
    which the ledger records on the same drop: a contact shrinking from a = 3 to 2 cells'
    width over stressed contents (above the new friction limits with friction)."""
    n = 40
    p = np.array([50.0, 1.2, -10.0, 0.5])  # R, E*/G*, x_lo, dx
    a_old, a_new = 3.0, 2.0
    d_old, d_new = a_old**2 / p[K.P_R], a_new**2 / p[K.P_R]
    base = np.zeros((K.work_rows(mu is not None), n))
    i0, i1 = K._contact_range(0.1, a_old, p[K.P_X_LO], p[K.P_DX], n)
    base[K.W_U, i0 : i1 + 1] = np.linspace(-0.2, 0.3, i1 - i0 + 1)
    res = {}
    for ledger in (True, None):
        W = base.copy()
        st = np.zeros(K.N_STATE)
        st[[K.ST_C, K.ST_A, K.ST_D]] = 0.1, a_old, d_old
        slip = K._set_radius(W, st, p, a_new, d_new, mu, ledger)
        res[ledger] = W, st, slip
    (W1, st1, slip1), (W0, st0, slip0) = res[True], res[None]
    np.testing.assert_array_equal(W0, W1, err_msg="contents differ without the ledger")
    assert slip0 == slip1 and st0[K.ST_SLIP] == st1[K.ST_SLIP], f"slip {slip0} vs {slip1}"
    assert st0[K.ST_T] == st1[K.ST_T], f"T {st0[K.ST_T]} vs {st1[K.ST_T]}"
    assert st1[K.ST_REL] > 0.0, "the ledger recorded no released energy on the drop"
    if mu is not None:
        assert slip1 > 0.0 and st1[K.ST_SNAP] > 0.0, (
            f"no slip ({slip1}) or snap ({st1[K.ST_SNAP]}): the case does not exceed the limits"
        )
    assert st0[K.ST_REL] == 0.0 and st0[K.ST_SNAP] == 0.0, "the env path wrote ledger energies"


@pytest.mark.parametrize("ticks_per_period", [2, 3, 7, 8, 1000])
def test_observation_clock_is_the_excitation_phase(ticks_per_period):
    """Observations 7 and 8 are sin and cos of 2 pi t / period at every step (read from a
    table of one period), to float32 precision, over two and a half periods."""
    env = rolling_env.make(
        "default", ticks_per_period=ticks_per_period, episode_steps=5 * ticks_per_period // 2 + 3
    )
    obs, _ = env.reset(seed=0)
    steps = 5 * ticks_per_period // 2
    zero = np.zeros(3, dtype=np.float32)
    for k in range(1, steps + 1):
        obs, *_ = env.step(zero)
        ph = 2 * math.pi * k / ticks_per_period
        assert abs(obs[7] - math.sin(ph)) <= 1e-6 and abs(obs[8] - math.cos(ph)) <= 1e-6, (
            f"step {k}: clock ({obs[7]}, {obs[8]}), expected ({math.sin(ph)}, {math.cos(ph)})"
        )


def test_scene_vector_carries_one_period_of_the_clock():
    """The clock table is one period long: its first entry is (0, 1), and it never needs an
    index past its end (k mod ticks_per_period)."""
    core = BatchCore(1, ticks_per_period=5)
    sv = core.sv
    assert sv.shape == (EK.N_SV + 10,), f"scene vector of shape {sv.shape}"
    assert (sv[EK.N_SV], sv[EK.N_SV + 1]) == (0.0, 1.0)
    assert int(sv[EK.S_TPP]) == 5


@pytest.mark.parametrize("resolution", [10.0, 12.0, 16.0, 37.3])
@pytest.mark.parametrize("scene", ["default", "heavy_inf_friction"])
def test_no_content_outside_the_contact(scene, resolution):
    """After every tick each cell outside the contact holds exactly zero content (the cells
    the load change and the energy sums see, ``_contact_range``): released and cut-off
    material leaves nothing behind.  400 ticks of 32 envs, random actions (force, lift-off,
    both rolling directions), resolutions with and without an exact 1/dx.  (Random contacts
    do not land within an ulp of a cell bound; the test below puts them there.)"""
    core = BatchCore(32, scene=scene, resolution=resolution)
    core.seed(3)
    core.reset()
    rng = np.random.default_rng(11)
    n_all = core.cells.shape[2]
    x_lo, levels = core.p[0, K.P_X_LO], int(core.p[0, K.P_LEVELS])
    assert core.max_episode_steps >= 400, "the run must not cross an episode end"
    for t in range(400):
        a = rng.uniform(-1, 1, (32, 3))
        a[rng.random(32) < 0.1, 0] = -1.0  # lift-off where N_min = 0
        core.step(a)
        for e in range(32):
            c, half = core.st[e, K.ST_C], core.st[e, K.ST_A]
            lv = int(core.st[e, K.ST_LEVEL])  # the level grid's cells in use
            dx, n = core.p[e, K.P_DX] / 2**lv, n_all >> (levels - lv)
            U = core.cells[e, K.W_U]
            i0, i1 = K._contact_range(c, half, x_lo, dx, n) if half > 0 else (n, -1)
            outside = np.r_[U[:i0], U[i1 + 1 :]]  # the finer levels' cells beyond n too
            assert not np.any(outside), (
                f"tick {t}, env {e}: content {outside[outside != 0]!r} "
                f"outside the contact cells {i0}..{i1} (c = {c!r}, "
                f"a = {half!r}, dx = {dx!r})"
            )


def _ulp_contact_ends():
    """(x_lo, dx, t) with a contact end t a few ulps from a cell bound x_lo + m dx where
    (t - x_lo) times 1/dx and (t - x_lo) / dx round to different cells."""
    cases = []
    x_lo = -8.0
    for dx in (1 / 10, 1 / 12, 1 / 24, 1 / 37.3, 0.3):
        for m in range(1, 300):
            for direction in (math.inf, -math.inf):
                t = x_lo + m * dx
                for _ in range(4):
                    t = math.nextafter(t, direction)
                    if math.floor((t - x_lo) * (1.0 / dx)) != math.floor((t - x_lo) / dx):
                        cases.append((x_lo, dx, t))
    return cases


def test_cells_a_tick_touches_are_the_cells_of_the_contact_at_ulp_level():
    """A contact whose leading end lies a few ulps past a cell bound, where rounding (t - x_lo)
    / dx by a product and by a quotient picks different cells: one tick (no rolling, the
    sphere translating, so every touched cell takes content in proportion to its overlap)
    leaves content only inside ``_contact_range`` of the end state, which the next load
    change cuts and the energy sums count.  Before both used ``_cell_floor``, the tick took
    the product and ``_contact_range`` the quotient: a cell of overlap ~1e-16 took content
    outside the range."""
    cases = _ulp_contact_ends()
    crossing = 0
    for x_lo, dx, t in cases:
        d, R = 0.25, 1.0
        a = math.sqrt(R * d)  # as the kernel computes it
        c = t - a
        if c + a != t:
            continue
        n = int((t - x_lo) / dx) + 4
        W = np.zeros((K.work_rows(False), n))
        st = np.zeros(K.N_STATE)
        st[K.ST_C], st[K.ST_A], st[K.ST_D] = c, a, d
        p = np.array([R, 1.2, x_lo, dx])
        out = np.zeros(K.N_OUT)
        K._tick(W, st, p, d, 0.0, 0.1, 0.0, None, 1.0, None, 1, 0.01, out, None)
        i0, i1 = K._contact_range(st[K.ST_C], st[K.ST_A], x_lo, dx, n)
        U = W[K.W_U]
        outside = np.r_[U[:i0], U[i1 + 1 :]]
        assert not np.any(outside), (
            f"x_lo = {x_lo!r}, dx = {dx!r}, contact end {t!r}: content "
            f"{outside[outside != 0]!r} outside cells {i0}..{i1}"
        )
        q = math.floor((t - x_lo) / dx)
        crossing += bool(U[q + 1] != 0.0) if q + 1 < n else 0
    assert crossing >= 5, (
        f"only {crossing} of {len(cases)} cases put content in the cell the "
        "quotient would miss: the test no longer probes the ulp case"
    )


def _exact_inner(i0, i1, full_lo, full_hi, x_lo, dx):
    """Cells of i0..i1 inside [full_lo, full_hi] by the cell bounds as the kernel computes them
    (x_lo + j dx and that plus dx), one by one."""
    return [
        j for j in range(i0, i1 + 1) if x_lo + j * dx >= full_lo and x_lo + j * dx + dx <= full_hi
    ]


@pytest.mark.parametrize(
    "x_lo,n", [(-8.0, 400), (-3.7e3, 100_000), (-1.9e6, 20_000_000), (2.5, 400)]
)
def test_inner_cells_are_never_outside_and_exact_but_within_the_margin(x_lo, n):
    """``_inner_range`` estimates the inner cells with a margin instead of testing the cell
    bounds (2-3% of the env step): it must never call a cell inner that is not inside the
    sub-step's full-contact interval by the exact cell-bound test (the inner cells' build
    assumes overlap dx), and it must equal that test except where an end lies within the
    margin of a cell bound (such a cell goes to the edge cells, exact as well).  Ends placed a
    few ulps either side of cell bounds, at resolutions whose 1/dx is not exact, near a row's
    start and deep in rows of up to 2e7 cells (the model's limit), plus random ends; also the
    load change's use (one contact, no travel) and travels longer than the contact."""
    rng = np.random.default_rng(11)
    n_near = n_cases = 0
    for dx in (1 / 10, 1 / 12, 1 / 37.3, 0.3, 1.7):
        xl = x_lo * dx * 10  # the row's start, |x_lo| / dx = 10 |x_lo|
        inv_dx = 1.0 / dx
        tol = K._inner_tol(xl, inv_dx, n)
        # the margin costs speed, not accuracy: a margin of a sizeable fraction of a cell
        # would pass every check below, so it is bounded here
        assert tol < 1e-4, f"margin {tol:.1e} cells"
        ends = [
            int(m) for m in np.r_[rng.integers(1, min(n, 300), 40), rng.integers(1, n - 50, 40)]
        ]
        ends += [n - 45 + k for k in range(6)]  # contacts reaching the row's end: i1 clamped
        for m in ends:
            for k_lo, k_hi in [(0, 0), (1, -1), (-1, 1), (3, -2), (-4, 4), (2, 2), (-2, -3)]:
                width = int(rng.integers(0, 40)) if m < n - 45 else 45 - (m - n + 45) % 3
                full_lo = xl + int(m) * dx
                full_hi = xl + (int(m) + width) * dx
                for _ in range(abs(k_lo)):
                    full_lo = math.nextafter(full_lo, math.copysign(math.inf, k_lo))
                for _ in range(abs(k_hi)):
                    full_hi = math.nextafter(full_hi, math.copysign(math.inf, k_hi))
                if rng.random() < 0.3:  # random ends, including no full cell at all
                    full_lo += float(rng.uniform(-1, 1)) * dx
                    full_hi = full_lo + float(rng.uniform(-2, 30)) * dx
                travel = int(rng.integers(0, 3))
                i0 = max(int(math.floor((full_lo - xl) * inv_dx)) - travel, 0)
                i1 = min(int(math.floor((full_hi - xl) * inv_dx)) + travel, n - 1)
                if i1 < i0:
                    continue
                j0, j1 = K._inner_range(i0, i1, full_lo, full_hi, xl, dx, inv_dx, tol)
                assert i0 <= j0 <= i1 + 1 and j0 - 1 <= j1 <= i1, (i0, i1, j0, j1)
                got = list(range(j0, j1 + 1))
                want = _exact_inner(i0, i1, full_lo, full_hi, xl, dx)
                n_cases += 1
                near = min(
                    abs((full_lo - xl) * inv_dx - round((full_lo - xl) * inv_dx)),
                    abs((full_hi - xl) * inv_dx - round((full_hi - xl) * inv_dx)),
                )
                n_near += near <= tol
                assert set(got) <= set(want), (
                    f"dx = {dx!r}, x_lo = {xl!r}: cells {sorted(set(got) - set(want))} called "
                    f"inner outside [{full_lo!r}, {full_hi!r}]"
                )
                if got != want:
                    assert near <= 2 * tol, (
                        f"dx = {dx!r}: cells {got[:1]}..{got[-1:]} for "
                        f"{want[:1]}..{want[-1:]}, ends {near:.1e} cells "
                        f"from a bound (margin {tol:.1e})"
                    )
    assert n_cases > 2000, n_cases
    assert n_near > 100, f"{n_near} ends within the margin: the test no longer probes it"


GOLDEN = Path(__file__).parent.parent / "data" / "golden_env.npz"


@pytest.mark.parametrize("scene", rolling_env.list_scenes())
def test_env_reproduces_its_recorded_transitions(scene):
    """128 seeded random steps of every shipped scene against the recorded trajectory
    (tests/make_golden.py; a speed-up must change it by round-off only): observations to 2e-6
    (float32), rewards and every info value to 1e-10 of their largest magnitude."""
    import make_golden

    ref = np.load(GOLDEN)
    new = make_golden.record(scene)
    keys = {k.split("/", 1)[1] for k in ref.files if k.startswith(scene + "/")}
    assert keys == set(new), f"{scene}: recorded {sorted(keys)}, now {sorted(new)}"
    for k in sorted(keys):
        old, cur = ref[f"{scene}/{k}"], new[k]
        assert old.shape == cur.shape, f"{scene}/{k}: shape {old.shape} -> {cur.shape}"
        if k == "obs":
            err = np.abs(cur - old).max()
            assert err <= 2e-6, f"{scene}: observations differ by up to {err:.1e}"
        else:
            err = np.abs(cur - old).max() / (np.abs(old).max() + 1e-300)
            assert err <= 1e-10, f"{scene}/{k}: differs by {err:.1e} of its largest value"


def test_env_drive_refuses_drive_run_and_old_pickles_load():
    """The env kernel keeps no energy ledger: ``Drive.run``, which keeps it, refuses an env's
    drive by name.  Its work array has the rows of the edge cells' dissipation (their start
    content and content integral, the wear's trailing-edge term), the same rows as the
    ledger's, in the single env and the batched one.  A drive pickled before the ledger had
    rows of its own (a plain ``ledger`` attribute and fewer rows) loads with the rows it
    needs."""
    import pickle

    import rolling_env
    from rolling_env.env.vector import BatchCore
    from rolling_env.physics.model import Drive

    env = rolling_env.make("default")
    drv = env.unwrapped.drive
    assert not drv.ledger
    assert drv.cells.shape[0] == K.work_rows(True, False) == K.work_rows(True), drv.cells.shape
    core = BatchCore(2, "default")
    assert core.cells.shape[1] == K.work_rows(True, False), core.cells.shape
    env.reset(seed=0)
    env.step(np.array([1.0, 0.5, 0.5], dtype=np.float32))
    assert np.any(drv.U != 0.0), "no contact after a step"
    with pytest.raises(RuntimeError, match="without the energy ledger"):
        drv.run(dt_tick=1e-6, n_sub=4, omega_R=[0.1], v=[0.1], N=[0.5])
    W, st, p = drv.cells[: K.W_L + 2].copy(), drv.st.copy(), drv._p
    with pytest.raises(ValueError, match="lacks the energy ledger's rows"):  # not past the rows
        K.run_ticks(
            W,
            st,
            p,
            np.array([0.1]),
            np.array([0.1]),
            np.array([0.1]),
            np.zeros(1),
            0.3,
            1.0,
            None,
            4,
            0.01,
            np.zeros((1, K.N_OUT)),
        )
    own = Drive(
        drv.params, a_ref=drv.L0, resolution=8, stroke=(-1e-4, 1e-4), a_max=drv.L0, t_ref=drv.t0
    )
    assert own.ledger and own.cells.shape[0] == K.work_rows(True)
    own.U[:] = np.linspace(0.0, 1.0, own.U.size)
    state = pickle.loads(pickle.dumps(own)).__dict__.copy()  # as pickled before: a plain
    state["ledger"] = state.pop("_ledger")  # attribute, fewer rows
    state["cells"] = state["cells"][: K.W_L + 2]
    older = Drive.__new__(Drive)
    older.__setstate__(state)
    assert older.ledger and older.cells.shape[0] == K.work_rows(True), older.cells.shape
    assert np.array_equal(older.U, own.U)


def _clipped_walk_integral(U0, s, xL, xR, c0, u, dt, a, d, inv3R, muEG, m=4000):
    """Reference for ``_edge_impulse``: the cell walked in m steps (``_walk``), its content
    clipped to the friction limit after each, the integral summed from each step's own."""
    h = dt / m
    U, total = U0, 0.0
    for k in range(m):
        c = c0 + u * k * h
        A, B, IA, IB, *_ = K._walk(U, xL, xR, c, a, u, K._inv_speed(u), h)
        total += IA + IB * s
        L = K._edge_limit(xL, xR, c + u * h, a, d, inv3R, muEG)[0]
        U = min(max(A + B * s, -L), L)
    return total


@pytest.mark.parametrize("over", [1.001, 1.01, 1.03])
def test_edge_impulse_of_a_cell_entering_stuck_that_starts_to_slide(over):
    """A cell entering the contact in a sub-step with a creep that takes it just beyond its
    limit by the end (``over`` x) stuck for most of the sub-step: its integral is within
    3e-4 of its end limit x dt of a 4000-step clipped walk (measured 2.3e-5 / 1.4e-4 / 4e-10;
    with its limit's integral alone, before the free integral bounded it, 1.5e-3 at 1.001)."""
    a, R, muEG = 1.0, 2.5, 0.24
    d, inv3R = a * a / R, 1 / (3 * R)
    xL, xR, c0, u, dt = a, a + 0.0625, 0.0, 1.0, 0.0625  # the cell enters at t = 0
    A, B, IA, IB, *_ = K._walk(0.0, xL, xR, c0, a, u, K._inv_speed(u), dt)
    Li = K._edge_limit(xL, xR, c0 + u * dt, a, d, inv3R, muEG)[0]
    s = over * Li / B
    got = K._edge_impulse(0.0, A + B * s, Li, IA + IB * s, s, xL, xR, c0, u, dt, a, d, inv3R, muEG)
    ref = _clipped_walk_integral(0.0, s, xL, xR, c0, u, dt, a, d, inv3R, muEG)
    assert abs(got - ref) <= 3e-4 * Li * dt, f"{(got - ref) / (Li * dt):.2e} of Li dt"


@pytest.mark.parametrize("th2", [0.0, 1e-8, 1e-3, 0.1, 0.2999, 0.3, 1.0, 30.0, 1e6])
def test_runner_step_functions_against_high_precision(th2):
    """``_phis`` (cos th, sin th / th, (1 - cos th) / th^2, (th - sin th) / th^3; series below
    th^2 = 0.3) against 40-digit arithmetic: 1e-14 relative (the limits at th = 0 exact)."""
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 40
    got = K._phis(th2)
    if th2 == 0.0:
        want = [1, 1, mp.mpf(1) / 2, mp.mpf(1) / 6]
    else:
        t = mp.sqrt(th2)
        want = [mp.cos(t), mp.sin(t) / t, (1 - mp.cos(t)) / t**2, (t - mp.sin(t)) / t**3]
    for name, g, w in zip(("cos", "p1", "p2", "p3"), got, want):
        assert abs(g - float(w)) <= 1e-14 * max(abs(float(w)), 1e-300) + 1e-300, (name, g, w)


@pytest.mark.parametrize("k", [0.0, 0.3, 40.0])
def test_runner_linear_solves_the_forced_oscillator(k):
    """``_runner_linear``: m xi'' = T0 + (Tf1 - T0) t / dt - k xi + F, xi(0) = 0, xi'(0) = v0,
    integrated by scipy (rtol 1e-12): mean velocity xi(dt)/dt, end velocity and end force
    T + F to 1e-9 of their scales, from a free mass (k = 0) to 6 rad per step."""
    from scipy.integrate import solve_ivp

    m, T0, Tf1, F, v0, dt = 1.1, 0.7, -0.4, 0.25, 0.3, 1.0
    sol = solve_ivp(
        lambda t, y: [y[1], (T0 + (Tf1 - T0) * t / dt - k * y[0] + F) / m],
        (0.0, dt),
        [0.0, v0],
        rtol=1e-12,
        atol=1e-14,
    )
    xi, v1 = sol.y[0, -1], sol.y[1, -1]
    vb, v1k, f1 = K._runner_linear(m, k, T0, Tf1, F, v0, dt)
    assert abs(vb - xi / dt) < 1e-9 and abs(v1k - v1) < 1e-9, (vb, xi / dt, v1k, v1)
    assert abs(f1 - (Tf1 - k * xi + F)) < 1e-9, (f1, Tf1 - k * xi + F)
