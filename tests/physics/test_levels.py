"""The level grid: finer cells for smaller contacts (``grid_levels``).

A contact of radius a on a grid of ``resolution`` cells per a_max radius has only
``resolution * a / a_max`` cells per radius of its own; at small loads that is a handful and the
contact's memory (the deflection it carries from tick to tick) is smeared.  A level grid halves
the cells (up to ``grid_levels`` times) as the contact shrinks and merges them back as it grows.
These tests check the remaps from their definition (conservation, exactness on a linear
profile, the choice of level) and the benefit against refined runs of the same episode.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import rolling_env
from rolling_env.env.scenes import load_scene
from rolling_env.physics import _kernel as K
from rolling_env.physics.model import Drive, DriveParams

R = 1e-3
A_MAX = 1.87e-5


def _drive(levels: int, resolution: float = 16.0, ledger: bool = False) -> Drive:
    params = DriveParams(R, 115.4e9, 95.0e9, mu=math.inf, m=math.inf)
    return Drive(
        params,
        a_ref=A_MAX,
        resolution=resolution,
        stroke=(-3 * A_MAX, 3 * A_MAX),
        a_max=A_MAX,
        t_ref=5e-5,
        ledger=ledger,
        levels=levels,
    )


def _overlaps(drv: Drive, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell bounds (units of a_ref) and overlaps with the contact held in ``drv.st``."""
    dx = drv.grid.dx / (1 << level)
    n = drv.grid.n << level
    xl = drv.grid.x_lo + np.arange(n) * dx
    c, a = drv.st[K.ST_C], drv.st[K.ST_A]
    ell = np.clip(np.minimum(xl + dx, c + a) - np.maximum(xl, c - a), 0.0, None)
    return xl, ell


def _linear_contents(drv: Drive, level: int, alpha: float, beta: float) -> np.ndarray:
    """Exact contents of uT = alpha + beta x over each cell's part in contact."""
    xl, ell = _overlaps(drv, level)
    dx = drv.grid.dx / (1 << level)
    c, a = drv.st[K.ST_C], drv.st[K.ST_A]
    lo = np.maximum(xl, c - a)
    hi = np.minimum(xl + dx, c + a)
    return np.where(ell > 0, alpha * ell + 0.5 * beta * (hi * hi - lo * lo), 0.0)


def _contact(drv: Drive, c: float, a: float, level: int = 0) -> None:
    drv.reset()
    drv.st[K.ST_C] = c
    drv.st[K.ST_A] = a
    drv.st[K.ST_D] = a * a / drv._p[K.P_R]
    drv.st[K.ST_LEVEL] = level


def test_split_and_merge_conserve_content_and_round_trip():
    """A split (level 0 -> 2) keeps the total content to round-off, and merging back gives
    every cell its content again (to 1e-13 of the largest); random contents."""
    drv = _drive(levels=3)
    _contact(drv, c=0.137, a=0.83)
    _, ell = _overlaps(drv, 0)
    rng = np.random.default_rng(3)
    U0 = np.where(ell > 0, rng.normal(size=ell.size) * ell, 0.0)
    n0 = drv.grid.n
    drv.U[:n0] = U0
    K._regrid(drv.cells, drv.st, drv._p, 2, None)
    assert drv.st[K.ST_LEVEL] == 2
    assert abs(drv.U.sum() - U0.sum()) < 1e-13 * np.abs(U0).sum(), "split changed the content"
    _, ell2 = _overlaps(drv, 2)
    assert np.all(drv.U[: n0 << 2][ell2 == 0] == 0.0), "content outside the contact"
    K._regrid(drv.cells, drv.st, drv._p, 0, None)
    np.testing.assert_allclose(
        drv.U[:n0],
        U0,
        rtol=0,
        atol=1e-13 * np.abs(U0).max(),
        err_msg="split then merge is not the identity",
    )
    assert np.all(drv.U[n0:] == 0.0), "the merge left content in the finer cells"


def test_split_is_exact_on_a_linear_deflection():
    """Cells wholly in contact whose neighbours are too are split by their linear
    reconstruction: on uT = alpha + beta x the children get the exact integrals (1e-12)."""
    drv = _drive(levels=2)
    _contact(drv, c=-0.21, a=0.77)
    drv.U[: drv.grid.n] = _linear_contents(drv, 0, 0.3, -1.7)
    K._regrid(drv.cells, drv.st, drv._p, 2, None)
    exact = _linear_contents(drv, 2, 0.3, -1.7)
    _, ell = _overlaps(drv, 2)
    dx2 = drv.grid.dx / 4
    # children of parents two or more cells inside the contact's ends
    inner = np.flatnonzero(ell >= dx2)[8:-8]
    np.testing.assert_allclose(
        drv.U[inner],
        exact[inner],
        rtol=0,
        atol=1e-12 * dx2,
        err_msg="a linear deflection is not split exactly",
    )


def test_cut_keeps_a_linear_deflection_where_the_new_contact_ends():
    """A load drop cuts the cell holding the new contact's end at the linear reconstruction:
    on a linear deflection its kept content is exact (1e-12) where its neighbours are in
    contact; infinite friction, so no snap."""
    drv = _drive(levels=0)
    _contact(drv, c=0.05, a=0.9)
    drv.U[:] = _linear_contents(drv, 0, -0.4, 2.3)
    a_new = 0.612345
    K._set_radius(drv.cells, drv.st, drv._p, a_new, a_new * a_new / drv._p[K.P_R], None, None)
    exact = _linear_contents(drv, 0, -0.4, 2.3)  # the state now holds the new contact
    np.testing.assert_allclose(
        drv.U,
        exact,
        rtol=0,
        atol=1e-12 * drv.grid.dx,
        err_msg="the cut does not keep the linear deflection",
    )


@pytest.mark.parametrize("res", [16.0, 32.0])
def test_level_keeps_between_half_and_twice_the_cells_per_radius(res):
    """The level chosen for a contact of radius a (a tick's load) gives it more than
    resolution/2 and at most 2 x resolution cells per radius wherever the finest level
    allows, along a random sequence of loads (hysteresis: the level held is kept while it
    is the one needed or the next finer)."""
    levels = 4
    rng = np.random.default_rng(0)
    lv = 0
    for a in np.concatenate([rng.uniform(0.0, 1.0, 400) ** 2, [1.0, 0.5, 0.25, 1e-3, 0.0]]):
        new = K._target_level(a, levels, lv)
        if a == 0.0:
            assert new == lv, "no contact must keep the level"
            continue
        cells = res * a * 2**new
        if a > 2.0**-levels:
            assert res / 2 < cells * (1 + 1e-9) and cells <= 2 * res * (1 + 1e-9), (a, lv, new)
        else:
            assert new == levels, (a, new)
        lv = new


def test_a_drive_with_levels_keeps_its_energy_ledger():
    """The merges' lost spread is booked as released energy: a drive with a level grid, a
    prescribed runner and random loads closes its energy balance as tightly as one without
    (residual within 1e-3 of the drive work) and stays within 2% of its displacement."""
    out = {}
    rng = np.random.default_rng(1)
    n = 400
    N = rng.uniform(0.0, 1.0, n)
    u = np.where(np.arange(n) % 8 < 4, 0.5, -0.5)  # a square wave: the patch stays on the row
    for levels in (0, 4):
        params = DriveParams(R, 115.4e9, 95.0e9, mu=0.3, m=1e-4)
        drv = Drive(
            params,
            a_ref=A_MAX,
            resolution=16.0,
            stroke=(-4 * A_MAX, 4 * A_MAX),
            a_max=A_MAX,
            t_ref=5e-5,
            levels=levels,
        )
        drv.reset()
        res = drv.run(dt_tick=5e-6, n_sub=40, omega_R=u, v=u * 0.99, N=N * 1.0)
        e = drv.energy
        assert abs(e["residual"]) < 1e-3 * e["work_in"], (levels, e)
        out[levels] = res["xstar"][-1]
    assert abs(out[4] - out[0]) < 0.02 * abs(out[0]) + 1e-12, out


def test_levels_bring_random_load_episodes_to_the_refined_value():
    """light_stiff under random actions (loads down to lift-off, 512 ticks) on 32 cells per
    a_max radius: with a level grid the final runner position is within 0.4 tolerance of the
    refined run (128 cells, the same sub-steps and levels; measured 0.27), without it beyond
    1.5 tolerances (measured 2.1).  The same sub-steps throughout: the grid's error only."""
    acts = np.random.default_rng(0).uniform(-1.0, 1.0, (512, 3)).astype(np.float32)

    def final(res, levels):
        env = rolling_env.make("light_stiff", sub_steps=60, resolution=res, grid_levels=levels)
        env.reset(seed=0)
        for a in acts:
            *_, info = env.step(a)
        return info["xstar"]

    tol = load_scene("light_stiff").tolerance
    ref = final(128.0, 4)
    with_levels = abs(final(32.0, 4) - ref) / tol
    without = abs(final(32.0, 0) - ref) / tol
    assert with_levels < 0.4, f"level grid: {with_levels:.2f} tolerances from the refined run"
    assert without > 1.5, f"one grid: {without:.2f} tolerances (expected beyond 1.5)"


@pytest.mark.parametrize("bad", [-1, 13, 2.5, True, "many"])
def test_grid_levels_out_of_range_is_one_clear_line(bad):
    with pytest.raises(ValueError, match="grid_levels") as e:
        rolling_env.make("default", grid_levels=bad)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("bad", [-1, 13, 1.5])
def test_drive_levels_out_of_range_is_one_clear_line(bad):
    with pytest.raises(ValueError, match="levels") as e:
        _drive(levels=bad)
    assert "\n" not in str(e.value)
