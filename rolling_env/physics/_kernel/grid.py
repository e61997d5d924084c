"""Remaps of the cell contents: to another level of a level grid (``_regrid``) and to a new
contact radius (``_set_radius``: the cut of a shrinking contact, the snap of the friction
limits on a load drop)."""

from __future__ import annotations

from numba import njit

from .cells import (
    _cells,
    _contact_range,
    _edge,
    _edge_limit,
    _edges,
    _inner_content,
    _inner_range,
    _inner_tol,
    _level_grid,
    _overlap,
    _slide,
)
from .layout import (
    _FM_INNER,
    JIT,
    JIT_INLINE,
    P_E_OVER_G,
    P_R,
    P_X_LO,
    ST_A,
    ST_C,
    ST_D,
    ST_LEVEL,
    ST_REL,
    ST_SLIP,
    ST_SNAP,
    ST_T,
    W_U,
)


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


@njit(**JIT_INLINE)
def _cut_slope(i, i_lo, i_hi, g_lo, g_hi):
    """The slope ``_shrink_cell`` reconstructs cell i with: those of the cells that hold the
    new contact's ends, 0 elsewhere."""
    return g_lo if i == i_lo else (g_hi if i == i_hi else 0.0)


@njit(**JIT_INLINE)
def _cut_edges(U, i0, i1, j0, j1, x_lo, dx, c, a_old, a_new, i_lo, i_hi, g_lo, g_hi, T):
    """The cut of the edge cells with infinite friction.  Returns (released energy, T)."""
    rel = 0.0
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
            _cut_slope(i, i_lo, i_hi, g_lo, g_hi),
        )
        rel += e_rel
        T += dU
    return rel, T


@njit(**JIT_INLINE)
def _cut_and_snap_edges(
    U, i0, i1, j0, j1, x_lo, dx, c, a_old, a_new, d_new, inv3R, muEG, cut, T, slip, snap
):
    """The cut of the edge cells with finite friction, each clipped to its new limit as the
    tick's commit clips (a cell cut off entirely has Ui = Li = 0).  ``cut``: (i_lo, i_hi, g_lo,
    g_hi) of ``_cut_slope``; T, slip, snap: the inner cells' sums (``_snap_inner``), which
    the edge cells' add to.  Returns (released energy, sum of the contents, Coulomb work,
    elastic energy lost beyond it)."""
    rel = 0.0
    for k in _edges(i0, i1, j0, j1):
        i = _edge(k, j0, j1)
        xL = x_lo + i * dx
        xR = xL + dx
        e_rel, _, ln = _shrink_cell(
            U, i, xL, dx, c, a_old, a_new, _cut_slope(i, cut[0], cut[1], cut[2], cut[3])
        )
        rel += e_rel
        Li, q = _edge_limit(xL, xR, c, a_new, d_new, inv3R, muEG)
        Ui = U[i]
        Uc, work, over = _slide(Ui, Li, q)
        if over and ln > 0.0:
            ex = abs(Ui) - Li
            snap += 0.5 * ex * ex / ln
        slip += work
        U[i] = Uc
        T += Uc
    return rel, T, slip, snap


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
    slip = 0.0
    snap = 0.0
    # cells inside the new contact (and so the old) lose nothing: only the edge cells are cut
    # (with finite friction the inner ones may still snap to their lowered limits)
    if a_new > 0.0:
        j0, j1 = _inner_range(
            i0, i1, c - a_new, c + a_new, x_lo, dx, inv_dx, _inner_tol(x_lo, inv_dx, n)
        )
    else:
        j0, j1 = i1 + 1, i1
    if mu is None:
        rel, T = _cut_edges(
            U, i0, i1, j0, j1, x_lo, dx, c, a_old, a_new, i_lo, i_hi, g_lo, g_hi, st[ST_T]
        )
        if a_new <= 0.0:
            T = 0.0  # lift-off: every cell released
    else:
        inv3R = 1.0 / (3.0 * p[P_R])
        muEG = mu * p[P_E_OVER_G]
        T, slip, snap = _snap_inner(W, j0, j1, x_lo, dx, c, muEG, d_new, inv3R, inv_dx)
        cut = (i_lo, i_hi, g_lo, g_hi)
        rel, T, slip, snap = _cut_and_snap_edges(
            U, i0, i1, j0, j1, x_lo, dx, c, a_old, a_new, d_new, inv3R, muEG, cut, T, slip, snap
        )
    if ledger is not None:  # without the ledger LLVM drops the energies' divisions
        st[ST_REL] += rel
        st[ST_SNAP] += snap
    st[ST_SLIP] += slip
    st[ST_T] = T
    return slip
