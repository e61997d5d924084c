"""Cattaneo-Mindlin tangential loading of a pressed sphere: the simulated force against the
analytic law (runner held, no rolling)."""

from __future__ import annotations

import numpy as np

from rolling_env.physics import analytic
from rolling_env.physics.experiments import DEFAULT_RESOLUTION, Geometry
from rolling_env.physics.model import Drive, DriveParams, check_n_sub
from rolling_env.validation import check_int, check_range

MINDLIN_MU_MAX = 1e3  # beyond it the slip distance u* = 3 mu N / (16 G* a1) leaves any contact
MINDLIN_POINTS_MAX = 10**5  # displacement points (ticks of one run)


def mindlin(mu, *, points=21, resolution=DEFAULT_RESOLUTION, geo: Geometry = Geometry(), n_sub=20):
    """Cattaneo-Mindlin: press with d1, then displace tangentially up to 1.2 u* (runner held).

    Returns ``u_over_ustar``, ``T_over_muN`` (simulated) and ``analytic`` lists."""
    check_range("mu", mu, 0.0, MINDLIN_MU_MAX, lo_open=True)
    points = check_int("points", points, 2, MINDLIN_POINTS_MAX)
    n_sub = check_n_sub(n_sub)
    check_range("resolution", resolution, 2.0, 1e5)
    a1 = geo.a1
    d1 = a1**2 / geo.R
    params = DriveParams(geo.R, geo.E_star, geo.G_star, mu=mu)
    drv = Drive(params, a_ref=a1, resolution=resolution, stroke=(0.0, 0.0), a_max=a1, t_ref=geo.tau)
    drv.reset()
    ustar = analytic.mindlin_ustar(mu, d1, geo.E_star, geo.G_star)
    N = analytic.hertz_force(d1, geo.R, geo.E_star)
    u = np.linspace(0.0, 1.2 * ustar, points)
    du = np.diff(u)
    dt = geo.tau
    # no rolling, runner held: creep rate -v = du/dt
    out = drv.run(
        dt_tick=dt,
        n_sub=n_sub,
        omega_R=np.zeros(du.size),
        v=-du / dt,
        d=np.full(du.size, d1),
        vstar=np.zeros(du.size),
    )
    T = np.concatenate([[0.0], out["T"]])
    ana = analytic.mindlin_force(u, mu, N, d1, geo.E_star, geo.G_star)
    return {
        "u_over_ustar": (u / ustar).tolist(),
        "T_over_muN": (T / (mu * N)).tolist(),
        "analytic": (np.asarray(ana) / (mu * N)).tolist(),
        "mu": mu,
        "resolution": resolution,
    }
