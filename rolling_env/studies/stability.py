"""Stability on stiff and extreme cases: a grid of runs, each checked and reported.

Every case returns whether all its outputs are finite, its energy balance, its run time, the
physical outcome and the case's own checks.  The tolerances (stated in the report):

* finite: every output of every tick is finite (no NaN or inf), no exception;
* energy ledger: residual / (drive + external work) > -``RESID_TOL`` (energy never created
  beyond 1%; a positive residual is energy the numerics dissipated), > -``RESID_TOL_ENV``
  (1e-3) for the cases at env settings.  The ledger (drive work, release, slip, snap, kinetic
  and elastic energy) is exact only as the sub-step shrinks, so it is checked at the
  validated sub-steps (``experiments.default_substeps``, or a scene's own) and not at the
  deliberately coarse steps of the "maximal rates" and "sub-steps" cases;
* state energy: elastic + kinetic energy <= the work put in (drive + external, or drive minus
  the work on a prescribed runner), up to a round-off floor of ``FLOOR`` x 2 G* a1^3 per
  period: checked everywhere, also at coarse steps;
* run time below ``TIME_LIMIT`` seconds;
* case checks: lift-off releases every spring (all cell contents exactly 0, T = 0, N = 0) and
  the contact re-forms; results converge as the sub-step shrinks; 100 cells per sub-step
  still give the working point; at env settings the final runner position of ever lighter
  runners approaches the massless runner's (``ENV_CONTINUITY_*``).

Cases "at env settings": the default scene with the runner mass set for omega_n/Omega = r
(``ENV_RATIOS``, and massless), driven by a square wave (``env_square_wave``) at the scene's
own tick and sub-steps through a drive built as the env builds it, with the ledger on.

Separately from PASS/FAIL, each free-runner case is repeated with 4x the sub-steps and the
change of its mean runner velocity is reported ("step check"): "NOT converged" where the change
exceeds ``STEP_TOL_REL`` of the value and ``STEP_TOL_ABS`` (in omega R); at env settings the
change of the final x* (``ENV_STEP_TOL_ABS`` scene tolerances, or ``STEP_TOL_REL``).  Where
the physics has no steady state the outcome column says so.
"""

from __future__ import annotations

import math
import time

from rolling_env.io import write_text
from rolling_env.physics import experiments as ex
from rolling_env.studies.stability_cases import (
    _liftoff_case,
    _long_case,
    _max_rates_free,
    _max_rates_wp,
    _no_steady_state,
    _sim,
    _substep_case,
)
from rolling_env.studies.stability_checks import (
    BASE,
    EPS_FRICTION,
    EPS_STICK,
    FLOOR,
    RESID_TOL,
    STEP_TOL_ABS,
    STEP_TOL_REL,
    TIME_LIMIT,
    _row,
)
from rolling_env.studies.stability_env import (
    ENV_PERIODS,
    ENV_RATIOS,
    ENV_SCENE,
    ENV_STEP_TOL_ABS,
    RESID_TOL_ENV,
    _env_case,
    _env_continuity_case,
    _EnvSweep,
)


# ----------------------------------------------------------------------------- the grid
def cases(quick=False):
    """(name, callable) pairs; ``quick``: the fastest subset (used by the tests)."""
    return (
        _runner_cases(quick)
        + _geometry_cases()
        + _extreme_cases(quick)
        + _env_cases([1.0, 100.0, 1e3, 1e4, math.inf] if quick else list(ENV_RATIOS), quick)
    )


def _runner_cases(quick):
    """Free runners over the runner mass and the friction coefficient."""
    d, w, r = BASE["delta"], BASE["w"], BASE["r"]
    c = []
    rs = (
        [1e-3, 1, 1e4, math.inf]
        if quick
        else [1e-3, 1e-2, 0.1, 1, 10, 1e2, 1e3, 1e4, 1e100, math.inf]
    )
    for rr in rs:
        c.append((f"mass: omega_n/Omega = {rr:g}, mu = inf", _sim(d, EPS_STICK, w, rr)))
        if not quick:
            c.append(
                (f"mass: omega_n/Omega = {rr:g}, mu = 0.3", _sim(d, EPS_FRICTION, w, rr, mu=0.3))
            )
    for mu in [1e-4, 0.1] if quick else [1e-4, 1e-2, 0.1, 1.0, math.inf]:
        c.append((f"friction: mu = {mu:g}", _sim(d, EPS_FRICTION, w, r, mu=mu)))
    if not quick:
        c.append(
            (
                "friction: mu = 1e-4 at eps = 0.1 (full sliding, creep per sub-step >> slip limit)",
                _sim(d, EPS_STICK, w, r, mu=1e-4),
            )
        )
    return c


def _geometry_cases():
    """The limits of delta and w, below w = 2 and below w = 2 sqrt(delta)."""
    w, r = BASE["w"], BASE["r"]
    c = []
    for dl in (1e-4, 1.0):
        c.append(
            (
                f"delta = {dl:g}",
                _sim(
                    dl,
                    EPS_STICK,
                    w,
                    r,
                    quasi_static=True,
                    note="exact limit: 1 - eps" if dl < 0.01 else "exact limit: 0",
                ),
            )
        )
    c.append(("w = 2.05, delta = 0.5", _sim(0.5, EPS_STICK, 2.05, r, quasi_static=True)))
    c.append(
        (
            "w = 1.8 < 2, delta = 0.5 (1 + sqrt(delta) <= w: corrected Eq. 32)",
            _sim(0.5, EPS_STICK, 1.8, r, quasi_static=True),
        )
    )
    c.append(("w = 0.5, delta = 0.5 (w < 2 sqrt(delta))", _no_steady_state(0.5, EPS_STICK, 0.5, r)))
    return c


def _extreme_cases(quick):
    """Lift-off mid-step, maximal rates, a long run and the sweep of sub-steps."""
    r = BASE["r"]
    c = [
        ("lift-off mid-step (N = 0 for one tick), mu = 0.3, free runner", _liftoff_case(0.3, r)),
        (
            "lift-off mid-step (N = 0 for one tick), mu = inf, prescribed runner",
            _liftoff_case(math.inf, 0.0),
        ),
        ("maximal rates: 100 and 6400 cells per sub-step, working point", _max_rates_wp()),
        (
            "maximal rates: 100 cells per sub-step, free runner, mu = inf",
            _max_rates_free(math.inf, r, ledger=True),
        ),
        (
            "maximal rates: 100 cells per sub-step, free runner, mu = 0.3",
            _max_rates_free(0.3, r, ledger=False),
        ),
    ]
    if not quick:
        c.append(
            (
                "maximal rates: 100 cells per sub-step, massless runner, mu = 0.3",
                _max_rates_free(0.3, math.inf, ledger=False),
            )
        )
    c.append(
        (
            "long run (2e4 ticks)" if quick else "long run (1e5 ticks)",
            _long_case(20_000 if quick else 100_000),
        )
    )
    c.append(
        (
            "sub-steps 1 .. 1e3 per half period" if quick else "sub-steps 1 .. 1e4 per half period",
            _substep_case((1, 10, 100, 1000) if quick else (1, 10, 100, 1000, 10000)),
        )
    )
    return c


def _env_cases(env_rs, quick):
    """The default scene's runner at env settings over omega_n/Omega ``env_rs``, and its
    continuity towards the massless runner; one sweep shared by all of them."""
    sweep = _EnvSweep()
    c = []
    for rr in env_rs:
        name = "massless" if math.isinf(rr) else f"omega_n/Omega = {rr:g}"
        c.append(
            (
                f"env settings ({ENV_SCENE} scene): {name}",
                _env_case(sweep, rr, step_check=not quick),
            )
        )
    c.append(
        (
            f"env settings ({ENV_SCENE} scene): x* tends to the massless runner's",
            _env_continuity_case(sweep, env_rs),
        )
    )
    return c


def status(r: dict, seconds: float, error=None) -> str:
    ok = (
        error is None
        and r["finite"]
        and r["state_ok"]
        and seconds < TIME_LIMIT
        and all(r["checks"].values())
        and (
            not r["ledger"]
            or not math.isfinite(r["residual"])
            or r["residual"] > -r.get("resid_tol", RESID_TOL)
        )
    )
    return "PASS" if ok else "FAIL"


def run(quick=False) -> list[dict]:
    rows = []
    for name, fn in cases(quick):
        t = time.perf_counter()
        err = None
        try:
            r = fn()
        except Exception as e:  # a crash is a failed case, reported
            err = e
            r = _row(False, float("nan"), False, f"raised {e!r}")
        sec = time.perf_counter() - t
        rows.append(dict(case=name, seconds=sec, status=status(r, sec, err), **r))
    return rows


def _fmt_resid(r):
    if not math.isfinite(r["residual"]):
        return "n/a"
    s = f"{r['residual']:.2e}"
    return s if r["ledger"] else s + " (not checked)"


def report(rows) -> str:
    lines = [
        "# Stability on stiff and extreme cases",
        "",
        "Generated by `rolling-drive stability` (2-core machine, one thread; seconds include "
        "the 4x-step repeat).  Unless a case says otherwise: delta 0.7, w 2.5, omega_n/Omega "
        "0.3, eps 0.1 with mu = inf and eps 0.995 with finite mu, 64 springs per a1, 20 "
        "periods, the default sub-steps of `experiments.default_substeps` (the patch moves at "
        f"most a1/{1 / ex.PATCH_TRAVEL_MAX:g} per sub-step, {ex.PATCH_CELLS_FRICTION:g} cell "
        f"with finite friction; {ex.RUNNER_STEPS_PER_PERIOD} sub-steps per runner period up "
        f"to omega_n/Omega = {ex.RUNNER_RESOLVED_MAX:g}, capped at that count up to "
        f"{ex.RUNNER_CAPPED_MAX:g}, not resolved above).  Cases 'at env settings': the "
        f"{ENV_SCENE} scene's own tick, sub-steps and resolution with the runner mass set for "
        f"omega_n/Omega = r (omega_n = sqrt(2 a_max G*/m), a_max the contact radius at N_max), "
        f"{ENV_PERIODS} periods of a square wave (forth N = 0.8 N_max, omega R = +0.7 "
        "omega_R_max; back N = 0.4 N_max, -0.7 omega_R_max; v = omega R (1 - 0.3 creep_max)); "
        "x* in the scene's tolerances, energies per period in 2 G* a_max^3.",
        "",
        "Criteria (PASS needs all):",
        "* **finite**: every output of every tick finite, no exception;",
        f"* **energy residual** = (work in - elastic - released - slip - snap - kinetic) / work "
        f"in > -{RESID_TOL:g} (> -{RESID_TOL_ENV:g} at env settings): energy never created "
        "beyond 1% (0.1%); positive: dissipated by the numerics (the uniform-cell mixing at "
        "the moving contact edges and, where the runner period is not resolved, the runner "
        "step's blend into backward Euler).  The work in is floored at "
        f"{FLOOR:g} x 2 G* a1^3 per period (a runner too light to load the contact).  The "
        "ledger is exact only as the step shrinks; it is not checked at the deliberately "
        "coarse steps (marked 'not checked');",
        f"* **state energy**: elastic + kinetic <= work in (+ {FLOOR:g} x 2 G* a1^3 per period "
        "round-off), checked everywhere;",
        f"* run time < {TIME_LIMIT:g} s; the case's own checks (named in the outcome).",
        "",
        f"**Step check** (not part of PASS): the change of the mean v*/(omega R) when the "
        f"sub-steps are multiplied by 4; 'NOT converged' above {STEP_TOL_REL:g} relative and "
        f"{STEP_TOL_ABS:g} absolute (at env settings: the change of the final x*, "
        f"{ENV_STEP_TOL_ABS:g} tolerance absolute).  Slip work is per period in units of "
        "2 G* a1^3; "
        "'stuck fraction' is the mean stuck share of the contact at the end of the ticks of "
        "the second half of the run.",
        "",
        "| case | status | finite | energy residual | state energy ok | seconds | step check "
        "| outcome |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['status']} | {r['finite']} | {_fmt_resid(r)} | "
            f"{r['state_ok']} | {r['seconds']:.2f} | {r['step']} | {r['outcome']} |"
        )
    fails = [r for r in rows if r["status"] != "PASS"]
    unconv = [r for r in rows if r["converged"] is False]
    lines += [
        "",
        f"**{len(rows) - len(fails)} passed, {len(fails)} failed; "
        f"{len(unconv)} not converged in the step at the default sub-steps.**",
    ]
    for r in fails:
        why = []
        if not r["finite"]:
            why.append("non-finite output or exception")
        if not r["state_ok"]:
            why.append("state energy exceeds the work put in")
        tol = r.get("resid_tol", RESID_TOL)
        if r["ledger"] and math.isfinite(r["residual"]) and r["residual"] <= -tol:
            why.append(
                f"energy ledger shows {-r['residual']:.2g} of the work put in created "
                f"(tolerance {tol:g})"
            )
        why += [f"check '{k}' failed" for k, v in r["checks"].items() if not v]
        if r["seconds"] >= TIME_LIMIT:
            why.append("too slow")
        lines.append(f"* FAIL {r['case']}: {'; '.join(why)}")
    for r in unconv:
        lines.append(f"* not converged in the step: {r['case']} (v* changes by {r['step']})")
    return "\n".join(lines) + "\n"


def write(rows, path="results/stability.md") -> str:
    text = report(rows)
    write_text(path, text)
    return text
