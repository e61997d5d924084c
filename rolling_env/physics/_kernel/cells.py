"""Cells of the spring row: index ranges (the contact's cells, the inner and the edge cells),
a cell's overlap with the contact, its normal content and friction limit, and the clip of a
content to its limit."""

from __future__ import annotations

import numpy as np
from numba import njit, uint64

from .layout import JIT, P_DX, P_LEVELS, ST_LEVEL


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
def _inner_limit(x_lo, dx, i, c, muEG, d, inv3R):
    """Friction limit of inner cell i (overlap dx) with the patch centre at c: muEG times the
    integral of uN over the cell, clamped at 0 (a NaN stays NaN for the flag checks)."""
    zl = (x_lo + i * dx) - c
    Li = muEG * dx * (d - (zl * zl + zl * (zl + dx) + (zl + dx) * (zl + dx)) * inv3R)
    return 0.0 if Li < 0.0 else Li


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
def _level_grid(n_all, st, p):
    """(cell size, cells in use) of the grid level held in ``st``: level k has cells of
    dx / 2^k over the same row, so n_all / 2^(levels - k) of the array's n_all columns."""
    lv = int(st[ST_LEVEL])
    return p[P_DX] / (1 << lv), n_all >> (int(p[P_LEVELS]) - lv)


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


@njit(inline="always", **JIT)
def _trailing(i, j0, u):
    """Edge cell i (outside the inner cells j0..) lies on the contact's trailing side: below
    the inner cells where the patch moves towards +x, above them where it moves towards -x.
    Only there does material leave the contact; a leading edge cell's uniform content mixes
    the entering material at zero deflection, an energy loss of the cell model that is no
    slip work."""
    return (i < j0) == (u > 0.0)


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
