"""What every stability case checks and how its row reads: the energy balance against the
work put in, finiteness, the step check at 4x the sub-steps, the reference working point."""

from __future__ import annotations

import math

import numpy as np

from rolling_env.physics import analytic
from rolling_env.physics import experiments as ex

RESID_TOL = 1e-2  # the ledger may not show energy created beyond 1% of the work put in
FLOOR = ex.ENERGY_FLOOR  # round-off floor of the energy checks, in 2 G* a1^3 per period
TIME_LIMIT = 60.0  # seconds per case on the 2-core machine
STEP_TOL_REL = 0.02  # step check: relative change of the mean v* at 4x sub-steps ...
STEP_TOL_ABS = 1e-4  # ... and absolute change in omega R (for runners that barely move)
GEO = ex.Geometry()
WORK_UNIT = 2 * GEO.G_star * GEO.a1**3  # [J]
# defaults of the cases (infinite friction: eps 0.1; finite friction: eps 0.995, where the
# creep is small enough that the contact partly sticks)
BASE = dict(delta=0.7, w=2.5, r=0.3)
EPS_STICK, EPS_FRICTION = 0.1, 0.995


# ----------------------------------------------------------------------------- helpers
def _balance(e: dict, periods: float, prescribed: bool):
    """(ledger residual relative to the work put in, state energy bounded by that work)."""
    floor = FLOOR * WORK_UNIT * max(periods, 1.0)
    rel = float(e["residual"] / max(e["work_in"], floor))
    supply = e["drive"] - e["runner"] if prescribed else e["drive"] + e["ext"] + e["kinetic_start"]
    state_ok = bool(e["elastic"] + e["kinetic"] <= supply + floor)
    return rel, state_ok


def _finite(values, arrays=()):
    return bool(
        all(math.isfinite(x) for x in values) and all(np.all(np.isfinite(a)) for a in arrays)
    )


def _eq_ref(delta, eps, w):
    """Quasi-static reference and its name, or (None, reason)."""
    if w >= 2:
        return float(analytic.eq32(delta, eps, w)), "Eq. 32"
    try:
        return float(analytic.working_point_ratio(delta, eps, w)), "Eq. 32 + (2-w)^3/6"
    except ValueError:
        return None, "no formula"


def _row(
    finite,
    residual,
    state_ok,
    outcome,
    *,
    ledger=True,
    checks=None,
    step="-",
    converged=None,
    details=None,
    resid_tol=RESID_TOL,
):
    return dict(
        finite=finite,
        residual=residual,
        state_ok=state_ok,
        outcome=outcome,
        ledger=ledger,
        checks=checks or {},
        step=step,
        converged=converged,
        details=details or {},
        resid_tol=resid_tol,
    )


def _step_check(v, v4):
    dv = abs(v4 - v)
    ok = dv <= max(STEP_TOL_REL * abs(v4), STEP_TOL_ABS)
    return f"{dv:.1e}{'' if ok else ' NOT converged'}", bool(ok)
