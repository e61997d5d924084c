"""The numba finite-volume kernel against the slow plain-numpy spring row
(rolling_env.physics.naive).

Both discretise the same continuum (physics.md) differently: the naive row converges
erratically (about 1-3% at 100-200 springs per radius), ours smoothly.  On random
piecewise-constant inputs the two must agree within the naive row's discretisation error at a
fine grid; the tolerances below are set from that (stated per assert).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rolling_env.physics import experiments as ex
from rolling_env.physics import naive
from rolling_env.physics.model import Drive, DriveParams

GEO = ex.Geometry()
a1 = GEO.a1
d1 = a1**2 / GEO.R


def _random_ticks(seed, k=24):
    rng = np.random.default_rng(seed)
    tau = GEO.tau
    d = d1 * rng.uniform(0.2, 1.0, k)
    u = (2 * 2.5 * a1 / tau) * rng.choice([-1.0, 1.0], k) * rng.uniform(0.3, 1.0, k)
    v = u * (1 - rng.uniform(-0.01, 0.01, k))
    return d, u, v, tau / 8


def _ours(params, d, u, v, dt, vstar, res=128, n_sub=40):
    c_reach = np.abs(u).sum() * dt
    drv = Drive(
        params, a_ref=a1, resolution=res, stroke=(-c_reach, c_reach), a_max=a1, t_ref=GEO.tau
    )
    drv.reset()
    return drv.run(dt_tick=dt, n_sub=n_sub, omega_R=u, v=v, d=d, vstar=vstar)


def _naive(params, d, u, v, dt, vstar, per_a=400, n_sub=40):
    c_reach = np.abs(u).sum() * dt + 2 * a1
    vstar = np.zeros_like(d) if vstar is None else vstar
    return naive.naive_run(
        R=params.R,
        E_star=params.E_star,
        G_star=params.G_star,
        mu=params.mu,
        m=params.m,
        F_ext=params.F_ext,
        x_lo=-c_reach,
        x_hi=c_reach,
        dx=a1 / per_a,
        d=d,
        omegaR=u,
        v=v,
        vstar=vstar,
        dt_tick=dt,
        n_sub=n_sub,
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_prescribed_runner_infinite_friction_random_inputs(seed):
    """Impulse per tick of a prescribed runner on random inputs.  Ours is grid-converged
    (128 vs 512 cells per radius agree to 1e-4 of the largest impulse); the naive row
    converges *to ours* at first order: doubling its grid halves the gap (factor < 0.65),
    and at 400 springs per radius the gap is below 4%."""
    d, u, v, dt = _random_ticks(seed)
    vstar = 0.003 * np.abs(u)
    p = DriveParams(GEO.R, GEO.E_star, GEO.G_star)
    a = _ours(p, d, u, v, dt, vstar)["impulse"]
    a_fine = _ours(p, d, u, v, dt, vstar, res=512, n_sub=80)["impulse"]
    scale = np.max(np.abs(a_fine))
    assert np.max(np.abs(a - a_fine)) < 1e-4 * scale, "our kernel is not grid-converged"
    gaps = [
        np.max(np.abs(_naive(p, d, u, v, dt, vstar, per_a=k, n_sub=n)["impulse"] - a_fine)) / scale
        for k, n in ((200, 20), (400, 40))
    ]
    assert gaps[1] < 0.65 * gaps[0] and gaps[1] < 4e-2, (
        f"naive row does not converge to our solution: gaps {gaps} (seed {seed})"
    )


@pytest.mark.parametrize("seed,mu,m", [(3, 0.3, 1e-3), (4, 0.1, 1e-2), (5, math.inf, 1e-3)])
def test_free_runner_random_inputs(seed, mu, m):
    """Free runner with friction on random inputs against the naive row (400 springs per
    radius, its runner on the implicit trapezoid rule): runner displacement within 2% of its
    range at 40 sub-steps per tick (measured 0.2-0.8%; 0.02-0.08% at 160), and slip work
    within 3% of the naive row's first-order extrapolation from 40 and 80 sub-steps (its
    slip work takes the friction limit at the end of each sub-step; measured 0.2-1.3%; 10-15%
    apart at 40 sub-steps alone)."""
    d, u, v, dt = _random_ticks(seed)
    p = DriveParams(GEO.R, GEO.E_star, GEO.G_star, mu=mu, m=m)
    a = _ours(p, d, u, v, dt, None)
    b = _naive(p, d, u, v, dt, None)
    rng_x = np.ptp(b["xstar"]) + 1e-30
    err = np.max(np.abs(a["xstar"] - b["xstar"])) / rng_x
    assert err < 2e-2, f"x* mismatch {err:.3e} of its range (seed {seed}, mu {mu})"
    if math.isfinite(mu):
        b2 = _naive(p, d, u, v, dt, None, n_sub=80)
        sa, sb = a["slip_work"].sum(), 2.0 * b2["slip_work"][-1] - b["slip_work"][-1]
        assert abs(sa - sb) < 3e-2 * sb, f"slip work {sa:.4e} vs naive {sb:.4e}"


def test_naive_row_converges_to_same_working_point():
    """Both kernels approach Eq. 32; ours at 64 springs per radius is closer than the naive
    row at 128 (the reason the finite-volume scheme exists)."""
    ours = ex.working_point(0.7, 0.1, 2.5, resolution=64)["rel_error"]
    ref = naive.working_point(0.7, 0.1, 2.5, 128)
    eq = ex.analytic.eq32(0.7, 0.1, 2.5)
    naive_err = abs(ref - eq) / eq
    assert ours < naive_err, f"ours {ours:.2e} should beat the naive row {naive_err:.2e}"
    assert naive_err < 5e-2, f"naive row is far off Eq. 32: {naive_err:.2e}"
