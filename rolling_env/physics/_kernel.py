"""Private numba kernels of the finite-volume MDR contact (see ``rolling_env.physics.model`` for the
checked API).

Discretisation
--------------
The 1-D MDR spring row is treated as the continuum it approximates: cell ``i`` covers
``[x_lo + i dx, x_lo + (i+1) dx]`` and stores the tangential *content*
``U_i = integral of uT over (cell intersected with contact)``.  Within a cell the deflection is
taken uniform (``uT = U_i / l_i`` with ``l_i`` the exact overlap of cell and contact).  Over a
sub-step the patch centre ``c`` moves linearly, so the overlap of every cell is piecewise linear
in time; the kernel integrates the creep ODE *exactly* over each linear piece
(``_walk``):

* entry (leading edge inside the cell)   ``dU/dt = s l``               (new material has uT = 0)
* full  (cell inside the contact)        ``dU/dt = s l``
* exit  (trailing edge inside the cell)  ``d(U/l)/dt = s``             (released material
carries the mean)
* both  (contact narrower than a cell)   ``d(U/l)/dt = s - |u| (U/l) / l``

with ``s = omega R - v - v*`` the creep rate.  Because the result is affine in ``s``, each cell
returns ``U_end = A + B s``; the runner equation (backward Euler, implicit in ``v*``) is then
solved exactly for infinite friction and by a safeguarded Newton/bisection on the monotone
piecewise-linear force for finite friction.  Entry and exit times inside a sub-step, partial
cells at both contact edges and the conservative remap when the contact radius jumps are all
exact within the uniform-cell model, which makes the error smooth and second order in ``dx``.

Units are whatever the caller scales to (``model.Drive`` uses length a_ref, time t_ref and
force G* a_ref^2, so ``G* = 1`` here and ``E_over_G = E*/G*``).

Feature specialisation: ``mu``, ``mass`` and ``load`` are ``None`` or float.  numba prunes the
``is None`` branches at compile time, so every scene gets a kernel that contains only what it
needs (no slip checks with infinite friction, no dynamics for a prescribed runner, no load term
without a load); each combination is compiled and cached once.  The energy ledger is a feature
too (``ledger``): without it (the env) an edge cell's content is integrated in closed form
(``_walk_content``) rather than walked piece by piece with the integrals the ledger needs.

Compiler options (``JIT``, for every kernel here and in ``_envkernel``):

* ``error_model="numpy"``: numba's default ("python") tests every float division for a zero
  divisor so that it can raise ZeroDivisionError (2-3% of an env step).  The divisors here are
  positive by construction; a 0/0 or x/0 would give NaN or inf, which the non-finite flag
  reports.
* ``_nrt=False`` (numba's own switch, private: its tests use it; ``_jit_options``): no
  reference counting.  These kernels allocate nothing; they only index arrays their caller
  owns for the whole call.  With counting on, every call of a non-inlined kernel and every
  per-env view (then ``U[e]``, ``A[e]``, ...; now ``W[e]``) counted its arrays up and down with
  atomic operations, about 45 per env step (measured with the four separate cell arrays of
  before the work array W): 5% of the serial kernel, and in the threaded batch both threads
  contended for the same counters (aggregate +12% without them).  A kernel that allocated
  would fail to compile, not misbehave.  ``env_step_parallel`` keeps counting (prange needs it).
* ``pipeline_class=_compiler.Compiler``: numba's default pipeline, compiled with LLVM's
  predicated loop tails where the CPU has AVX-512 (the cell loops run 8 cells wide with a
  masked last iteration instead of a 16-wide body, a 4-wide epilogue and a scalar remainder:
  2-3% of the env step); the options are set only while our kernels compile (see
  ``_compiler``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

from rolling_env.physics._compiler import Compiler


def _jit_options() -> dict:
    """``cache``, ``error_model="numpy"``, the pipeline of ``_compiler`` (LLVM's predicated
    loop tails, where they apply) and, where this numba has it, ``_nrt=False`` (see the
    module docstring).  ``_nrt`` is private: should a numba release drop it, the kernels keep
    reference counting (about 5% slower) rather than fail to compile (numba refuses unknown
    options at the first call); tests/physics/test_kernel_paths.py says so with the numba tested."""
    opts = dict(cache=True, error_model="numpy", pipeline_class=Compiler)
    try:
        from numba.core.cpu import CPUTargetOptions

        if hasattr(CPUTargetOptions, "_nrt"):
            opts["_nrt"] = False
    except Exception:  # numba's internals moved: keep the counting
        pass
    return opts


JIT = _jit_options()

# ----------------------------------------------------------------------------- state layout
#: the per-env state vector, slot by slot; the ST_* indices are read from this one list
STATE_NAMES = (
    "c",  # patch centre c (spring frame)
    "a",  # contact half-width a currently in force
    "d",  # indentation d currently in force
    "vs",  # runner velocity v*
    "xs",  # runner displacement x*
    "xsph",  # sphere translation (integral of v dt)
    "T",  # tangential force T
    "imp",  # cumulative impulse of T
    "slip",  # cumulative slip work (friction dissipation, wear measure)
    "rel",  # cumulative release work (elastic energy carried off by released material)
    "drive",  # cumulative drive work  integral T (omega R - v) dt
    "runner",  # cumulative work of T on the runner  integral T v* dt
    "ext",  # cumulative work of F_ext on the runner
    "time",  # time
    "flag",  # error flags (bit field, see FLAG_*)
    "iter",  # cumulative Newton iterations (finite friction, free runner)
    "snap",  # cumulative elastic energy lost beyond the Coulomb work when springs snap to
    # the lower friction limit of an instantaneous normal-load drop
    "kin0",  # runner's kinetic energy at reset: the ledger's starting balance (written by
    # Drive.reset, read by Drive.energy; the kernel never touches it)
    "level",  # grid level k of a level grid (``P_LEVELS`` > 0): cells of dx / 2^k
)
_ST = {name: i for i, name in enumerate(STATE_NAMES)}
ST_C, ST_A, ST_D, ST_VS, ST_XS = _ST["c"], _ST["a"], _ST["d"], _ST["vs"], _ST["xs"]
ST_XSPH, ST_T, ST_IMP, ST_SLIP, ST_REL = _ST["xsph"], _ST["T"], _ST["imp"], _ST["slip"], _ST["rel"]
ST_DRIVE, ST_RUNNER, ST_EXT, ST_TIME = _ST["drive"], _ST["runner"], _ST["ext"], _ST["time"]
ST_FLAG, ST_ITER, ST_SNAP, ST_KIN0 = _ST["flag"], _ST["iter"], _ST["snap"], _ST["kin0"]
ST_LEVEL = _ST["level"]
N_STATE = len(STATE_NAMES)

# (omega_n dt)^2 (omega_n on the stuck contact) at which the runner step is half-way from
# the exact (piecewise) scheme to backward Euler (``_blend``)
THETA2_BLEND = 4.0

FLAG_GRID = 1  # the contact reached the end of the spring row
FLAG_NONFINITE = 2  # a non-finite value appeared (kernel stopped)
FLAG_SLIDE = 4  # massless runner with no force equilibrium (|F_ext| > mu N)

# per-tick outputs, in order; the OUT_* indices are read from this one list
OUT_NAMES = (
    "T",  # T at the end of the tick
    "imp",  # impulse of T over the tick
    "vs",  # v* at the end of the tick
    "xs",  # x* at the end of the tick
    "slip",  # slip work during the tick
    "c",  # patch centre at the end of the tick
    "N",  # normal force
    "stick",  # stuck fraction of the contact length at the end of the tick (1 with mu = inf)
)
_OUT = {name: i for i, name in enumerate(OUT_NAMES)}
OUT_T, OUT_IMP, OUT_VS, OUT_XS = _OUT["T"], _OUT["imp"], _OUT["vs"], _OUT["xs"]
OUT_SLIP, OUT_C, OUT_N, OUT_STICK = _OUT["slip"], _OUT["c"], _OUT["N"], _OUT["stick"]
N_OUT = len(OUT_NAMES)

# rows of the cell work array W (``Drive.cells``, ``BatchCore.cells[e]``; cells along the
# second axis): the tangential contents U, the build pass's A and B (U_end = A + B s), then,
# with finite friction only, the friction work rows L = W[W_L:] (L_* below).  One array
# rather than four separate ones: one argument instead of three for each non-inlined kernel,
# and one env's rows together in memory
W_U, W_A, W_B, W_L = 0, 1, 2, 3

# rows of the friction work array L = W[W_L:]
L_LIMIT = 0  # friction limit mu E*/G* integral of uN over the cell's part in contact
L_QLIM = 1  # an edge cell's friction limit per unit overlap (mu E*/G* times the mean uN
# over its part in contact; 0: none in contact), the mean of its values at
# the sub-step's start and end: the slip work's limit
L_U0, L_IA, L_IB = 2, 3, 4  # of an edge cell, its content at the start of the sub-step and
# its unclipped integral over it, IA + IB s (the wear's trailing-edge term,
# ``_edge_dissipation``, and the ledger's ``_edge_impulse``)
N_LCOL = 5


def work_rows(finite_mu: bool, ledger: bool = True) -> int:
    """Rows of the work array W: U, A, B and, with finite friction, the N_LCOL rows of L (the
    same with the energy ledger and without: ``ledger`` is kept for the callers that say
    which they build)."""
    return W_L + (N_LCOL if finite_mu else 0)


# params vector
P_R = 0
P_E_OVER_G = 1
P_X_LO = 2
P_DX = 3  # cell size at level 0
P_LEVELS = 4  # finest level of the level grid (0: a fixed grid, ``_regrid``)
N_PARAM = 5


@njit(inline="always", **JIT)
def _cells(lo, hi):
    """range(lo, hi) over cell indices as unsigned integers: numba then indexes the cell
    arrays without its negative-index wrap-around (three integer operations per access: a
    clip-and-sum loop over 21 cells took 27 ns with signed and 13 ns with unsigned indices on
    the project's machine).  Callers clamp lo >= 0 wherever the range is not empty; hi < lo
    (a contact that left the row) gives an empty range."""
    return range(uint64(lo), uint64(max(hi, lo)))


@njit(inline="always", **JIT)
def _edges(i0, i1, j0, j1):
    """The edge cells of i0..i1 (those outside the inner cells j0..j1) as ``for k in
    _edges(...)`` with cell ``_edge(k, j0, j1)``: the loop skips the inner block."""
    return _cells(i0, i1 + 1 - (j1 - j0 + 1))


@njit(inline="always", **JIT)
def _edge(k, j0, j1):
    """Cell of edge position k (see ``_edges``): below the inner block, or past it."""
    return k if k < uint64(j0) else k + uint64(j1 - j0 + 1)


@njit(inline="always", **JIT)
def _overlap(xL, xR, c, a):
    lo = max(xL, c - a)
    hi = min(xR, c + a)
    return hi - lo if hi > lo else 0.0


@njit(inline="always", **JIT)
def _normal_content(xL, xR, c, a, d, inv3R):
    """Integral of uN = d - (x - c)^2 / R over the cell's part in contact (inv3R = 1/(3R))."""
    lo = max(xL, c - a)
    hi = min(xR, c + a)
    if hi <= lo:
        return 0.0
    val = _inner_content(lo - c, hi - c, d, inv3R)
    return val if val > 0.0 else 0.0


@njit(inline="always", **JIT)
def _edge_limit(xL, xR, c, a, d, inv3R, muEG):
    """Friction limit of a cell's part in contact, muEG times the integral of uN over it, and
    that limit per unit overlap (muEG times the mean uN: no division); (0, 0) out of contact."""
    lo = max(xL, c - a)
    hi = min(xR, c + a)
    if hi <= lo:
        return 0.0, 0.0
    zl = lo - c
    zh = hi - c
    q = muEG * (d - (zl * zl + zl * zh + zh * zh) * inv3R)
    q = q if q > 0.0 else 0.0
    return (hi - lo) * q, q


@njit(inline="always", **JIT)
def _inner_content(zl, zh, d, inv3R):
    """Integral of d - z^2 / R over [zl, zh] (both inside the contact)."""
    return (zh - zl) * (d - (zl * zl + zl * zh + zh * zh) * inv3R)


@njit(inline="always", **JIT)
def _cell_floor(x, x_lo, inv_dx):
    """floor((x - x_lo) / dx), as a float, by multiplying with inv_dx = 1.0 / dx.  The one
    expression for the cell holding a contact end: the sub-steps' touched cells and
    ``_contact_range`` (load change, energy sums) take it with the same operands, so a cell
    that a tick gave content to is one the load change cuts and the sums count (within an
    ulp of a cell bound, a product and a quotient can round to different cells)."""
    return np.floor((x - x_lo) * inv_dx)


@njit(inline="always", **JIT)
def _contact_range(c, a, x_lo, dx, n):
    """First and last cell touching the contact [c - a, c + a], clamped to the row (i0 in
    [0, n], i1 in [-1, n - 1]: an empty range for a contact beyond either end)."""
    inv_dx = 1.0 / dx
    i0 = _index(_cell_floor(c - a, x_lo, inv_dx), 0, n)
    i1 = _index(_cell_floor(c + a, x_lo, inv_dx), -1, n - 1)
    return i0, i1


@njit(inline="always", **JIT)
def _index(q, lo, hi):
    """The integral float q (np.floor / np.ceil: numba's math.floor already converts to int)
    as an int clamped to [lo, hi], clamped in floating point first: a q beyond the int64
    range (a contact far off the row) or NaN gives an end of the range, never an undefined
    float-to-int conversion."""
    if q >= hi:
        return hi
    if q >= lo:
        return int(q)
    return lo


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
            dtp = _duration(q - p, inv_au, au)
            la = p + a - pL
            IA += A * dtp
            IB += B * dtp + 0.5 * la * dtp * dtp + au * dtp * dtp * dtp / 6.0
            B += dtp * (la + 0.5 * au * dtp)
        elif p < b2:
            q = min(b2, p_end)
            dtp = _duration(q - p, inv_au, au)
            if wide:
                ell = pR - pL
                IA += A * dtp
                IB += B * dtp + 0.5 * ell * dtp * dtp
                B += ell * dtp
            else:
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
                e2 += c2 * (
                    g * g * dtp + 2.0 * g * (B - g) * em1 / k + (B - g) * (B - g) * em2 / (2.0 * k)
                )
                A = A * (1.0 - em1)
                B = B * (1.0 - em1) + g * em1
        elif p < b3:
            q = min(b3, p_end)
            dtp = _duration(q - p, inv_au, au)
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
    (tests/physics/test_kernel_paths.py)."""
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


@njit(inline="always", **JIT)
def _inv_speed(u):
    """1/|u| for ``_walk``, or 0 where it would overflow (|u| <= 1e-300)."""
    au = abs(u)
    return 1.0 / au if au > 1e-300 else 0.0


@njit(inline="always", **JIT)
def _slope(U, i, xL, dx, c, a, n):
    """Slope of the deflection across cell i (inside the contact c +- a) from its neighbours'
    mean deflections at their parts' centroids, minmod-limited (0 at an extremum, or where a
    neighbour is out of contact or off the row): the linear reconstruction that the remaps
    (a cut, a finer grid) use to place content within a cell."""
    if i < 1 or i + 1 >= n:
        return 0.0
    return _slope3(U[i - 1], U[i], U[i + 1], xL, dx, c, a)


@njit(inline="always", **JIT)
def _slope3(Ul, U0, Ur, xL, dx, c, a):
    """``_slope`` of a cell [xL, xL + dx] wholly in contact with contents Ul, U0, Ur (left,
    own, right)."""
    lo_l = max(xL - dx, c - a)
    l_l = xL - lo_l
    hi_r = min(xL + 2.0 * dx, c + a)
    l_r = hi_r - (xL + dx)
    if l_l <= 0.0 or l_r <= 0.0:
        return 0.0
    u0 = U0 / dx
    gl = (u0 - Ul / l_l) / (xL + 0.5 * dx - 0.5 * (lo_l + xL))
    gr = (Ur / l_r - u0) / (0.5 * (xL + dx + hi_r) - (xL + 0.5 * dx))
    if gl * gr <= 0.0:
        return 0.0
    return gl if abs(gl) < abs(gr) else gr


@njit(inline="always", **JIT)
def _shrink_cell(U, i, xL, dx, c, a_old, a_new, g):
    """Release the part of cell i cut off when the contact shrinks from a_old to a_new.  A cell
    that was wholly in contact keeps the content of its linear reconstruction (slope g,
    ``_slope``) over the part still in contact; an edge cell keeps its uniform share.  Returns
    (released elastic energy, change of content, new overlap)."""
    lo = _overlap(xL, xL + dx, c, a_old)
    ln = _overlap(xL, xL + dx, c, a_new)
    if lo > 0.0 and ln < lo:
        Ui = U[i]
        Un = Ui * ln / lo
        if ln > 0.0 and lo >= dx and g != 0.0:
            xm = xL + 0.5 * dx
            zl = max(xL, c - a_new) - xm
            zh = min(xL + dx, c + a_new) - xm
            Un += 0.5 * g * (zh * zh - zl * zl)
        U[i] = Un
        return 0.5 * Ui * Ui / lo - (0.5 * Un * Un / ln if ln > 0.0 else 0.0), Un - Ui, ln
    return 0.0, 0.0, ln


@njit(inline="always", **JIT)
def _level_grid(n_all, st, p):
    """(cell size, cells in use) of the grid level held in ``st``: level k has cells of
    dx / 2^k over the same row, so n_all / 2^(levels - k) of the array's n_all columns."""
    lv = int(st[ST_LEVEL])
    return p[P_DX] / (1 << lv), n_all >> (int(p[P_LEVELS]) - lv)


@njit(inline="always", **JIT)
def _target_level(a, levels, lv):
    """The level for a contact of half-width a (units of a_ref, where the grid has its
    resolution): the coarsest whose cells give the contact at least half the cells per radius
    that a_ref has, floor(log2(1/a)), capped at ``levels``.  The level held (``lv``) is kept
    while it is that one or the next finer, so that a load dithering about a level boundary
    does not remap at every tick."""
    if a <= 0.0:
        return lv  # no contact: nothing to remap, the next contact decides
    k = 0
    r = a
    while r < 0.5 - 1e-9 and k < levels:
        r *= 2.0
        k += 1
    if lv == k or lv == k + 1:
        return lv
    return k


@njit(**JIT)
def _regrid(W, st, p, lv_new, ledger):
    """Move the contents to grid level ``lv_new``, conservatively: a merge (a larger contact)
    sums the children's contents; a split (a smaller contact) gives the children of a cell
    wholly in contact the content of its linear reconstruction (``_slope3``) over them, and
    those of an edge cell shares in proportion to their overlaps.  Merging loses the spread of
    the children's deflections, elastic energy that the ledger counts as released."""
    U = W[W_U]
    n_all = U.shape[0]
    dx_o, n_o = _level_grid(n_all, st, p)
    lv_o = int(st[ST_LEVEL])
    c = st[ST_C]
    a = st[ST_A]
    x_lo = p[P_X_LO]
    st[ST_LEVEL] = lv_new
    dx_n, n_n = _level_grid(n_all, st, p)
    if a <= 0.0:
        return
    i0, i1 = _contact_range(c, a, x_lo, dx_o, n_o)
    if lv_new > lv_o:
        m = 1 << (lv_new - lv_o)
        u_r = 0.0  # the content of the cell above, before it was split
        for i in range(i1, i0 - 1, -1):  # children m i.. lie at or above i: top down
            val = U[i]
            U[i] = 0.0
            xL = x_lo + i * dx_o
            lp = _overlap(xL, xL + dx_o, c, a)
            g = 0.0
            if lp >= dx_o and i > 0:  # wholly in contact: split its linear reconstruction
                g = _slope3(U[i - 1], val, u_r, xL, dx_o, c, a)
            u_r = val
            if lp <= 0.0:
                continue
            f = val / lp
            xm = xL + 0.5 * dx_o
            for j in range(m * i, m * i + m):
                xc = x_lo + j * dx_n
                lc = _overlap(xc, xc + dx_n, c, a)
                U[j] = f * lc + g * lc * (xc + 0.5 * dx_n - xm) if lc > 0.0 else 0.0
    else:
        m = 1 << (lv_o - lv_new)
        lost = 0.0
        for q in range(i0 // m, i1 // m + 1):  # parent q at or below its children: bottom up
            val = 0.0
            e = 0.0
            for j in range(m * q, min(m * q + m, n_o)):
                uj = U[j]
                val += uj
                if ledger is not None and uj != 0.0:
                    xc = x_lo + j * dx_o
                    e += 0.5 * uj * uj / _overlap(xc, xc + dx_o, c, a)
                U[j] = 0.0
            U[q] = val
            if ledger is not None and val != 0.0:
                xq = x_lo + q * dx_n
                lost += e - 0.5 * val * val / _overlap(xq, xq + dx_n, c, a)
        if ledger is not None:
            st[ST_REL] += lost


@njit(**JIT)
def _set_radius(W, st, p, a_new, d_new, mu, ledger):
    """Instantaneous change of the indentation to d_new (contact half-width a_new).

    Shrinking releases the cut-off part of each edge cell (uniform content); growing adds
    material with zero deflection (content unchanged).  With finite friction a load drop also
    lowers every friction limit at once: springs above it snap to it, doing Coulomb work
    (returned, and added to the slip work) and losing the rest of their excess elastic energy
    (``ST_SNAP``).  ``ledger`` None (the env) leaves the two energies of the ledger,
    ``ST_REL`` and ``ST_SNAP``, out (their divisions were about 1% of the default env step);
    the contents, T and the slip work are the same either way."""
    U = W[W_U]
    a_old = st[ST_A]
    d_old = st[ST_D]
    st[ST_A] = a_new
    st[ST_D] = d_new
    if a_new >= a_old and d_new >= d_old:
        return 0.0
    c = st[ST_C]
    x_lo = p[P_X_LO]
    dx, n = _level_grid(U.shape[0], st, p)
    inv_dx = 1.0 / dx
    i0, i1 = _contact_range(c, a_old, x_lo, dx, n)
    # the cells holding the new contact's ends, and their slopes before any cell is cut
    i_lo, i_hi = _contact_range(c, a_new, x_lo, dx, n)
    g_lo = _slope(U, i_lo, x_lo + i_lo * dx, dx, c, a_old, n) if a_new > 0.0 else 0.0
    g_hi = _slope(U, i_hi, x_lo + i_hi * dx, dx, c, a_old, n) if a_new > 0.0 else 0.0
    rel = 0.0
    slip = 0.0
    snap = 0.0
    T = 0.0
    # cells inside the new contact (and so the old) lose nothing: only the edge cells are cut
    # (with finite friction the inner ones may still snap to their lowered limits)
    if a_new > 0.0:
        j0, j1 = _inner_range(
            i0, i1, c - a_new, c + a_new, x_lo, dx, inv_dx, _inner_tol(x_lo, inv_dx, n)
        )
    else:
        j0, j1 = i1 + 1, i1
    if mu is None:
        T = st[ST_T]
        for k in _edges(i0, i1, j0, j1):
            i = _edge(k, j0, j1)
            e_rel, dU, _ = _shrink_cell(
                U,
                i,
                x_lo + i * dx,
                dx,
                c,
                a_old,
                a_new,
                g_lo if i == i_lo else (g_hi if i == i_hi else 0.0),
            )
            rel += e_rel
            T += dU
        if a_new <= 0.0:
            T = 0.0  # lift-off: every cell released
    else:
        inv3R = 1.0 / (3.0 * p[P_R])
        muEG = mu * p[P_E_OVER_G]
        T, slip, snap = _snap_inner(W, j0, j1, x_lo, dx, c, muEG, d_new, inv3R, inv_dx)
        for k in _edges(i0, i1, j0, j1):
            i = _edge(k, j0, j1)
            xL = x_lo + i * dx
            xR = xL + dx
            e_rel, _, ln = _shrink_cell(
                U, i, xL, dx, c, a_old, a_new, g_lo if i == i_lo else (g_hi if i == i_hi else 0.0)
            )
            rel += e_rel
            # the clip-and-slip of the tick's commit (a cell cut off entirely has Ui = Li = 0)
            Li, q = _edge_limit(xL, xR, c, a_new, d_new, inv3R, muEG)
            Ui = U[i]
            Uc, work, over = _slide(Ui, Li, q)
            if over and ln > 0.0:
                ex = abs(Ui) - Li
                snap += 0.5 * ex * ex / ln
            slip += work
            U[i] = Uc
            T += Uc
    if ledger is not None:  # without the ledger LLVM drops the energies' divisions
        st[ST_REL] += rel
        st[ST_SNAP] += snap
    st[ST_SLIP] += slip
    st[ST_T] = T
    return slip


@njit(inline="always", **JIT)
def _slide(Ut, Li, q):
    """A content Ut beyond its friction limit +-Li slides to it.  Returns (the clipped
    content, the slip work, whether it slid).  The slip work is the friction force Li times
    the slid distance (|Ut| - Li) / overlap, i.e. (|Ut| - Li) q with ``q`` = Li / overlap,
    the limit per unit overlap (stored for the edge cells, so that the tick divides by no
    overlap; 0 for a cell out of contact).  Branch-free (selects, and min/max
    for the clip): the loops in ``_commit`` and ``_snap_inner`` vectorise with it, and their
    scalar remainders (the last 1-3 cells) have no branch to mispredict: written as nested
    conditionals, the clip compiled to two branches there (2-3% of the env step with
    friction).  A NaN content stays NaN (numba's max and min return their first argument
    when it is NaN), so the non-finite check still sees it."""
    ex = abs(Ut) - Li
    over = ex > 0.0
    work = ex * q if over else 0.0
    return min(max(Ut, -Li), Li), work, over


@njit(inline="always", **JIT)
def _clip_slope(Ut, Li, Bi):
    """Content clipped to the friction limit +-Li and its slope dU/ds (Bi stuck, 0 sliding)."""
    Uc = min(max(Ut, -Li), Li)  # branch-free; a NaN content still reaches the commit's check
    return Uc, (Bi if Uc == Ut else 0.0)


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


@njit(inline="always", **JIT)
def _inner_tol(x_lo, inv_dx, n):
    """Margin, in cells, of ``_inner_range``'s estimates: over 1000 times the rounding of the
    estimate (full - x_lo) / dx against the cell bounds x_lo + j dx and x_lo + j dx + dx, which
    is at most about 7 n + 2 |x_lo| / dx + 5 units in the last place for cells 0..n.  About
    2e-10 cells on the shipped scenes, 4e-5 in a row of 2e7 cells."""
    return 1e-12 * (1.0 + n + abs(x_lo) * inv_dx)


@njit(inline="always", **JIT)
def _inner_range(i0, i1, full_lo, full_hi, x_lo, dx, inv_dx, tol):
    """Cells j0..j1 of i0..i1 that lie inside [full_lo, full_hi] (inside the contact during the
    whole sub-step); j1 = j0 - 1 when there is none, with i0 <= j0 <= i1 + 1 so that i0..j0-1
    and j1+1..i1 are the edge cells.  Estimated from the quotients with the margin ``tol``
    (``_inner_tol``) on the safe side: no cell outside [full_lo, full_hi] is ever inner, and a
    cell inside it whose bound lies within ``tol`` cells of full_lo or full_hi is left to the
    edge cells, which integrate any cell exactly (the same result to round-off).  Exact
    floating-point tests against the cell bounds, as before, cost 2-3% of the env step."""
    j0 = _index(np.ceil((full_lo - x_lo) * inv_dx + tol), i0, i1 + 1)
    j1 = _index(np.floor((full_hi - x_lo) * inv_dx - tol) - 1.0, j0 - 1, i1)
    return j0, j1


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


# Floating-point sums of the cell loops (the inner cells; in the env's commit every cell of
# the contact) may be reordered (reassoc), which lets LLVM vectorise them (numba leaves the
# SLP vectoriser off, and the loop vectoriser keeps in-order sums scalar): 1.4x per env-step
# on the default scene, and sums that differ from the in-order ones at round-off level
# (relative 1e-15 to 1e-12 on trajectories).  Only these two flags: no
# nnan/ninf (NaN and inf still reach the flag checks), no contract/arcp (the cell-bound tests
# elsewhere rely on exact floating-point comparisons; they are not in these functions, which
# numba compiles separately: inline="always" would drop their fastmath flags).
_FM_INNER = {"reassoc", "nsz"}


@njit(inline="always", **JIT)
def _inner_limit(x_lo, dx, i, c, muEG, d, inv3R):
    """Friction limit of inner cell i (overlap dx) with the patch centre at c: muEG times the
    integral of uN over the cell, clamped at 0 (a NaN stays NaN for the flag checks)."""
    zl = (x_lo + i * dx) - c
    Li = muEG * dx * (d - (zl * zl + zl * (zl + dx) + (zl + dx) * (zl + dx)) * inv3R)
    return 0.0 if Li < 0.0 else Li


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


@njit(fastmath=_FM_INNER, **JIT)
def _snap_inner(W, j0, j1, x_lo, dx, c, muEG, d_new, inv3R, inv_dx):
    """Load drop over the inner cells j0..j1 (inside the new contact: nothing cut off, overlap
    dx): contents above the new friction limit snap to it.  Returns (sum of the contents,
    Coulomb work, elastic energy lost beyond it)."""
    T = 0.0
    slip = 0.0
    snap = 0.0
    for i in _cells(j0, j1 + 1):
        zl = (x_lo + i * dx) - c
        val = _inner_content(zl, zl + dx, d_new, inv3R)
        Li = muEG * (val if val > 0.0 else 0.0)
        Ui = W[W_U, i]
        ex = abs(Ui) - Li
        Ui, work, over = _slide(Ui, Li, Li * inv_dx)  # overlap dx
        slip += work
        snap += 0.5 * ex * ex * inv_dx if over else 0.0
        W[W_U, i] = Ui
        T += Ui
    return T, slip, snap


# ----------------------------------------------------------------- the ledger's impulse
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


@njit(inline="always", **JIT)
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


@njit(inline="always", **JIT)
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


@njit(inline="always", **JIT)
def _trailing(i, j0, u):
    """Edge cell i (outside the inner cells j0..) lies on the contact's trailing side: below
    the inner cells where the patch moves towards +x, above them where it moves towards -x.
    Only there does material leave the contact; a leading edge cell's uniform content mixes
    the entering material at zero deflection, an energy loss of the cell model that is no
    slip work."""
    return (i < j0) == (u > 0.0)


@njit(inline="always", **JIT)
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


@njit(**JIT)
def _tick(W, st, p, d, u, v, vs_presc, mu, mass, load, n_sub, dt, out, ledger):  # noqa: C901 (the compiled tick, one inlined body)
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
    tests/physics/test_kernel_paths.py).

    Passes over the cells per sub-step: with infinite friction one build pass (A, B) and the
    commit; with finite friction and a free runner the build pass also evaluates the runner
    equation at v0, one Newton step gives the root of the piece active there, and the commit
    verifies it (a kink crossed sends the sub-step to ``_solve_bracketed`` and commits again).
    Cells inside the contact for the whole sub-step (A = U, B = dx dt) take a branch-free
    build loop (``_build_inner``); only the few edge cells are integrated one by one
    (``_walk`` with the ledger, ``_walk_content`` without).  The commit takes every cell in
    one branch-free loop (``_commit``) in the env with friction; elsewhere (no friction, or the
    ledger) the inner cells take that loop and the edge cells a scalar one.  The loops' sums
    may be reordered so that LLVM vectorises them.  B of the inner cells is never written
    by the build pass (the commit uses dx dt for them): it holds stale values except just
    before a call of ``_solve_bracketed`` (finite friction), which reads it.
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
    levels = int(p[P_LEVELS])
    if levels > 0:  # the new contact's level first: a cut and a snap then act on its cells
        lv = _target_level(a, levels, int(st[ST_LEVEL]))
        if lv != int(st[ST_LEVEL]):
            _regrid(W, st, p, lv, ledger)
    slip_tick = _set_radius(W, st, p, a, d, mu, ledger)
    dx, n = _level_grid(W.shape[1], st, p)
    U = W[W_U, :n]
    A = W[W_A, :n]
    B = W[W_B, :n]
    L = W[W_L:, :n]
    inv_dx = 1.0 / dx
    dxdt = dx * dt
    tol = _inner_tol(x_lo, inv_dx, n)
    s0 = u - v
    F = 0.0
    if load is not None:
        F = load
    imp_tick = 0.0
    stuck = 0.0
    # the state the sub-steps advance, kept in locals (st may alias the cell arrays for the
    # compiler, which would reload and store it around every cell loop); written back below
    c1 = st[ST_C]
    v1 = st[ST_VS]
    T1 = st[ST_T]
    xs = st[ST_XS]
    xsph = st[ST_XSPH]
    time = st[ST_TIME]
    slip_acc = st[ST_SLIP]
    iters = st[ST_ITER]
    for k_sub in range(n_sub):
        last = k_sub == n_sub - 1
        c0 = c1
        c1 = c0 + u * dt
        v0 = v1
        # cells touched: union of the contact at c0 and c1
        f0 = _cell_floor(min(c0, c1) - a, x_lo, inv_dx)  # as _contact_range at the end
        f1 = _cell_floor(max(c0, c1) + a, x_lo, inv_dx)
        if not (f0 >= 0.0 and f1 <= n - 1.0):
            st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_GRID
        i0 = _index(f0, 0, n)
        i1 = _index(f1, -1, n - 1)
        full_lo = max(c0, c1) - a
        full_hi = min(c0, c1) + a
        SA = 0.0
        SB = 0.0
        SIA = 0.0
        SIB = 0.0
        E0 = 0.0
        E1 = 0.0
        E2 = 0.0
        SL = 0.0
        # runner equation evaluated at v0 (finite friction, free runner)
        sv0 = s0 - v0
        Tt0 = 0.0
        dT0 = 0.0
        if a > 0.0:
            j0, j1 = _inner_range(i0, i1, full_lo, full_hi, x_lo, dx, inv_dx, tol)
        else:
            j0 = i1 + 1
            j1 = i1
        n_in = j1 - j0 + 1
        # ------------------------------------------------ build: inner cells (A = U, B = dx dt)
        SU, Tt0, dT0 = _build_inner(W, j0, j1, x_lo, dx, c1, muEG, d, inv3R, dxdt, sv0, mu, mass)
        if n_in > 0:
            SA += SU
            SB += n_in * dxdt
            if ledger is not None:
                SIA += SU * dt
                SIB += n_in * 0.5 * dxdt * dt
        # ------------------------------------------------ build: edge cells (integrated one by one)
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
        # ---------------------------------------------------------------- runner
        # vb: the runner's mean velocity over the sub-step (its displacement / dt), which the
        # cells' creep takes (s = s0 - vb); v1: its velocity at the end.  A free runner
        # (mass > 0) on the piece of the contact's force law active at v0 is a linear
        # oscillator forced by a ramp, propagated exactly (``_runner_linear``); with friction
        # a step that crosses a kink of the force law solves g(vb) = mass (vb - vref) -
        # h (T(s0 - vb) + Fs) = 0 (monotone), exact on the piece and a trapezoid in the
        # force beyond it (``_solve_runner`` with h = dt/2)
        fast = True
        vref = v0
        Fs = F
        h = dt
        vb = v0
        v1l = v0
        lam = 1.0
        if mass is None:
            vb = vs_presc
            v1 = vs_presc
        elif mu is None:
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
        else:
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
        if not abs(dt * SB) < np.inf:
            # the contact's stiffness times the step overflows: the runner step cannot be
            # formed (it would take a finite force for none); reported as non-finite
            st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_NONFINITE
        # ---------------------------------------------------------------- commit
        drift = (0.0, 0.0)
        if mu is not None:
            drift = _limit_drift(x_lo, dx, c0, c1, muEG, inv3R)
        for attempt in range(2):
            s = s0 - vb
            # branch-free (a cell beyond its limit slides to it, adding the slip work; the
            # others add exactly 0 to it): the env with friction commits every cell in one
            # loop (inner cells: B = dx dt and overlap dx; edge cells: the B and the limit per
            # unit overlap of the build pass); otherwise the inner cells, then the edge cells
            # one by one
            edge_cells = _edges(i0, i1, j0, j1)
            dimp = 0.0
            clipped = False
            T1_in = 0.0  # with the ledger and friction: T of the inner cells at the end
            if ledger is None and mu is not None:
                T1, Ta, slip, _ns, _nk, _nh = _commit(
                    W, i0, i1, j0, j1, dxdt, s, inv_dx, mu, mass, True, None, drift
                )
                edge_cells = _cells(0, 0)  # committed too: none left for the scalar loop
                if a > 0.0 and u != 0.0:
                    # the trailing edge cells' slip work is their dissipation
                    # (``_edge_dissipation``)
                    for k in _edges(i0, i1, j0, j1):
                        i = _edge(k, j0, j1)
                        if not _trailing(i, j0, u):
                            continue
                        xL = x_lo + i * dx
                        Ut0 = A[i] + B[i] * s
                        Li = L[L_LIMIT, i]
                        _u, work, _o = _slide(Ut0, Li, L[L_QLIM, i])
                        slip += (
                            _edge_dissipation(
                                L[L_U0, i],
                                Ut0,
                                U[i],
                                Li,
                                L[L_IA, i] + L[L_IB, i] * s,
                                s,
                                xL,
                                xL + dx,
                                c0,
                                c1,
                                u,
                                dt,
                                a,
                                d,
                                inv3R,
                                muEG,
                            )
                            - work
                        )
            elif ledger is not None and mu is not None:
                T1, Ta, slip, n_slid, n_kinks, n_held = _commit(
                    W, j0, j1, j0, j1, dxdt, s, inv_dx, mu, mass, None, True, drift
                )
                clipped = n_slid > 0
                if n_kinks > 0:
                    dimp, n_bent = _impulse_fix(W, j0, j1, x_lo, dx, c0, muEG, d, inv3R, dxdt, s)
                    n_held -= n_bent
                # the inner cells that stayed at their limit follow it, a quadratic in time
                # whose curvature (-2 muEG dx u^2 / R for the +limit) the trapezoid misses
                dimp += n_held * (muEG * dx * inv3R * 0.5) * (u * dt) * (u * dt)
                T1_in = T1
            else:
                T1, Ta, slip, _ns, _nk, _nh = _commit(
                    W, j0, j1, j0, j1, dxdt, s, inv_dx, mu, mass, None, None, drift
                )
            for k in edge_cells:
                i = _edge(k, j0, j1)
                Ut = A[i] + B[i] * s
                if mu is not None:
                    Ut0 = Ut
                    Ut, work, over = _slide(Ut, L[0, i], L[L_QLIM, i])
                    clipped |= over
                    if a > 0.0 and u != 0.0 and _trailing(i, j0, u):
                        xL = x_lo + i * dx
                        slip += _edge_dissipation(
                            L[L_U0, i],
                            Ut0,
                            Ut,
                            L[L_LIMIT, i],
                            L[L_IA, i] + L[L_IB, i] * s,
                            s,
                            xL,
                            xL + dx,
                            c0,
                            c1,
                            u,
                            dt,
                            a,
                            d,
                            inv3R,
                            muEG,
                        )
                    else:
                        slip += work
                    if mass is not None:
                        Ta += abs(Ut)
                U[i] = Ut
                T1 += Ut
            if mu is None or mass is None or not fast:
                break
            # verify the one-step root: g(vb) vanishes unless the step crossed a kink
            iters += 1.0
            g1 = mass * (vb - vref) - h * (T1 + Fs)
            if _converged(g1, mass, vb, vref, h, Ta, Fs):
                break
            fast = False
            st[ST_ITER] = iters
            B[j0 : j1 + 1] = dxdt
            vb = _solve_runner(A, B, L, i0, i1, s0, vref, vb, mass, Fs, h, st)
            iters = st[ST_ITER]
        if mu is not None and mass is not None:
            # end velocity: the piece's exact one, plus the momentum of the force beyond it
            # (blended with backward Euler's, the mean); a massless runner's is its mean
            v1 = vb
            if mass > 0.0:
                v1 = _end_velocity(lam, v1l, vb, vref, dt, h)
        if last and mu is not None:
            stuck = _stuck_length(W, i0, i1, j0, j1, x_lo, dx, c1, a)
        xs += vb * dt  # the displacement: the integral of v* over the sub-step
        xsph += v * dt
        slip_acc += slip
        if ledger is not None:
            if clipped and mu is not None:
                imp_edge = 0.0  # the edge cells' contents integrated over the sub-step
                if a > 0.0:
                    for k in _edges(i0, i1, j0, j1):
                        i = _edge(k, j0, j1)
                        xL = x_lo + i * dx
                        imp_edge += _edge_impulse(
                            L[L_U0, i],
                            A[i] + B[i] * s,
                            L[L_LIMIT, i],
                            L[L_IA, i] + L[L_IB, i] * s,
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
                work_r = (
                    lam * (0.5 * mass * (v1 - v0) * (v1 + v0) - F * vb * dt) + (1.0 - lam) * work_r
                )
            st[ST_IMP] += imp
            if mu is None:
                st[ST_REL] += E0 + s * (E1 + s * E2)
            st[ST_DRIVE] += s0 * imp
            st[ST_RUNNER] += work_r
            if load is not None:
                st[ST_EXT] += load * vb * dt
            imp_tick += imp
        time += dt
        slip_tick += slip
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
        out[OUT_STICK] = min(stuck / (2.0 * a), 1.0)
    if not (
        math.isfinite(T1) and math.isfinite(v1) and math.isfinite(xs) and math.isfinite(slip_tick)
    ):
        st[ST_FLAG] = int(st[ST_FLAG]) | FLAG_NONFINITE


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
