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

import numpy as np

from . import _kernel as _K
from . import analytic, scenes
from . import experiments as ex
from .excitation import SquareWave
from .io import write_text
from .model import Drive, DriveParams

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


# ----------------------------------------------------------------------------- free runner
def _sim(delta, eps, w, r, mu=math.inf, periods=20, quasi_static=False, note=""):
    """Square wave on a free runner at the default sub-steps, plus the 4x-step check."""

    def run():
        res = ex.simulate(delta, eps, w, r, mu=mu, periods=periods, record=True)
        tr = res["trajectory"]
        v = res["mean_v_star_over_omega_R"]
        finite = _finite([v, res["slip_work"], res["energy_residual"]], tr.values())
        rel, state_ok = _balance(res["energy"], periods, prescribed=(r == 0))
        res4 = ex.simulate(delta, eps, w, r, mu=mu, periods=periods, n_sub=4 * res["n_sub"])
        v4 = res4["mean_v_star_over_omega_R"]
        step, conv = _step_check(v, v4)
        ref, ref_name = _eq_ref(delta, eps, w)
        parts = [f"v*/(omega R) {v:.4g}"]
        if ref is not None:
            parts[0] += f" ({ref_name} {ref:.4g})"
        half = tr["stick_fraction"][tr["stick_fraction"].size // 2 :]
        if math.isfinite(mu):
            parts.append(
                f"slip work {res['slip_work']:.3g} per period, stuck fraction {half.mean():.2f}"
            )
        if quasi_static:
            wp = ex.working_point(delta, eps, w)
            parts.append(f"quasi-static working point {wp['simulated']:.5g}")
        steady, v3, v4q = _steady(res, periods)
        if not steady:
            parts.append(
                f"NOT at steady state: mean v* over the 3rd / 4th quarter of the run "
                f"{v3:.3g} / {v4q:.3g}"
                + (
                    " (heavy runner: relaxation time ~ 1/r^2 periods >> run)"
                    if 0 < r <= 0.01
                    else " (contact sliding: the runner is dragged by friction)"
                    if math.isfinite(mu) and half.mean() < 0.05
                    else ""
                )
            )
        if math.isinf(r):
            parts.append("massless runner: force equilibrium, follows the sphere, no net motion")
        elif not res["step_converged"]:
            nrp = res["runner_steps_per_period"]
            if r > ex.RUNNER_CAPPED_MAX:
                parts.append(
                    f"runner period not resolved ({nrp:.2g} sub-steps per runner "
                    f"period; the default resolves omega_n/Omega <= "
                    f"{ex.RUNNER_CAPPED_MAX:g}): the runner step blends into backward "
                    "Euler and gives the massless limit, runner follows the sphere"
                )
            else:
                parts.append(
                    f"runner period resolved by only {nrp:.3g} sub-steps (the "
                    f"default caps them above omega_n/Omega = "
                    f"{ex.RUNNER_RESOLVED_MAX:g}): mean v* not guaranteed converged "
                    "in the step"
                )
        elif r >= 2 and ref is not None:
            parts.append(f"stiff runner: {v / ref:.2g} x {ref_name}")
        elif ref is not None and 0.5 <= r <= 2 and v > ref:
            parts.append("resonant band: above the quasi-static value")
        if rel > 0.1:
            rel4 = res4["energy_residual"]
            if res["runner_steps_per_period"] < math.pi:
                parts.append(
                    f"{rel:.0%} of the work put in is dissipated by the numerics: the "
                    "runner period is not resolved (omega_n dt > 2), and the runner "
                    "step's blend into backward Euler damps the runner's ringing"
                )
            elif abs(rel4 - rel) <= 0.1 * rel:
                wl = 2 * w * ex.DEFAULT_RESOLUTION / r  # 2 pi omega R / omega_n, in cells
                parts.append(
                    f"{rel:.0%} of the work put in is dissipated by the numerics, "
                    f"the same at 4x the sub-steps ({rel4:.0%}): the uniform cells "
                    "average out the runner's ringing imprinted on the stuck contact "
                    f"(its wavelength 2 pi omega R / omega_n is {wl:.2g} cells), "
                    "large against the little work a runner this light draws"
                )
            else:
                parts.append(
                    f"{rel:.0%} of the work put in is dissipated by the numerics "
                    f"({rel4:.0%} at 4x the sub-steps)"
                )
        if note:
            parts.append(note)
        return _row(
            finite,
            rel,
            state_ok,
            "; ".join(parts),
            step=step,
            converged=conv,
            details=dict(v=v, v4=v4, n_sub=res["n_sub"]),
        )

    return run


def _steady(res, periods, tol=0.05):
    """(steady, v over the 3rd quarter, v over the 4th quarter) of a recorded run, in omega R."""
    x = res["trajectory"]["xstar"]
    wave = res["wave"]
    per = x.size // periods
    q = periods // 4
    if q < 1:
        return True, float("nan"), float("nan")
    scale = q * wave.tau * wave.omega_R * wave.direction
    v3 = (x[-q * per - 1] - x[-2 * q * per - 1]) / scale
    v4 = (x[-1] - x[-q * per - 1]) / scale
    return bool(abs(v4 - v3) <= tol * abs(v4) + 1e-8), float(v3), float(v4)


def _no_steady_state(delta, eps, w, r):
    """w < 2 sqrt(delta): the quasi-static 'working point' drifts with the run length."""
    base = _sim(delta, eps, w, r)

    def run():
        row = base()
        drift = [
            ex.working_point(delta, eps, w, periods=p, until_steady=False)["simulated"]
            for p in (3, 10, 30)
        ]
        row["outcome"] += (
            "; NO STEADY STATE (w < 2 sqrt(delta): some springs never release): "
            "quasi-static zero-impulse v*/(omega R) after 3 / 10 / 30 periods "
            + " / ".join(f"{x:.3g}" for x in drift)
            + ", decaying"
        )
        row["details"]["drift"] = drift
        return row

    return run


# ----------------------------------------------------------------------------- lift-off
def liftoff(mu=0.3, r=0.3, resolution=64, lift_tick=9):
    """Normal force to zero for one tick in the middle of a forth step (tick ``lift_tick`` of
    4 ticks per half period), given as N = 0 through ``Drive.run(N=...)``.

    Returns the checks: every cell content exactly 0, T = 0, N = 0 (kernel and discrete sum)
    after the lift-off tick, contact re-formed on the next tick, all outputs finite, and the
    energy ledger.  ``r = 0``: prescribed runner at the Eq. 32 working point; ``r = inf``:
    massless runner (T = 0 throughout, so only N tells that the contact is loaded)."""
    eps = EPS_FRICTION if math.isfinite(mu) else EPS_STICK
    wave = SquareWave(BASE["delta"], eps, BASE["w"], GEO.a1, GEO.R, GEO.tau)
    m = ex.natural_frequency_mass(r, wave, GEO.G_star)
    drv = Drive(
        DriveParams(GEO.R, GEO.E_star, GEO.G_star, mu=mu, m=m),
        a_ref=GEO.a1,
        resolution=resolution,
        stroke=wave.stroke,
        a_max=GEO.a1,
        t_ref=GEO.tau,
    )
    drv.reset()
    tph = 4
    d, u, v = wave.ticks(3, tph)
    N = analytic.hertz_force(d, GEO.R, GEO.E_star)
    n_sub = ex.default_substeps(r, wave, resolution, tph, mu)
    vs = None
    if math.isinf(m):
        vs = np.full(d.size, analytic.eq32(BASE["delta"], eps, BASE["w"]) * wave.omega_R)

    def seg(a, b, NN=None):
        return drv.run(
            dt_tick=wave.dt_tick(tph),
            n_sub=n_sub,
            omega_R=u[a:b],
            v=v[a:b],
            N=N[a:b] if NN is None else NN,
            vstar=None if vs is None else vs[a:b],
        )

    before = seg(0, lift_tick)
    lifted = seg(lift_tick, lift_tick + 1, NN=np.zeros(1))
    U_max = float(np.max(np.abs(drv.U)))
    N_sum = drv.normal_force()
    after = seg(lift_tick + 1, d.size)
    outs = (before, lifted, after)
    finite = _finite([], [a for o in outs for a in o.values()])
    rel, state_ok = _balance(drv.energy, 3, prescribed=math.isinf(m))
    carries = m != 0.0  # a massless runner is in force equilibrium: T = 0 throughout
    checks = {
        "loaded before": bool(before["N"][-1] > 0 and (before["T"][-1] != 0.0 or not carries)),
        "all cells released": U_max == 0.0,
        "T = 0": bool(lifted["T"][-1] == 0.0),
        "N = 0": bool(lifted["N"][-1] == 0.0 and N_sum == 0.0),
        "stuck fraction 0": bool(lifted["stick_fraction"][-1] == 0.0),
        "contact re-forms": bool(after["N"][0] > 0 and (after["T"][0] != 0.0 or not carries)),
    }
    return dict(
        finite=finite,
        residual=rel,
        state_ok=state_ok,
        checks=checks,
        U_max=U_max,
        T_before=float(before["T"][-1]),
        T_lift=float(lifted["T"][-1]),
    )


def _liftoff_case(mu, r):
    def run():
        x = liftoff(mu, r)
        ok = all(x["checks"].values())
        failed = [k for k, v in x["checks"].items() if not v]
        return _row(
            x["finite"],
            x["residual"],
            x["state_ok"],
            f"T before lift-off {x['T_before']:.3g} N; after: max |U| = {x['U_max']:g}, "
            f"T = {x['T_lift']:g}, N = 0; contact re-forms on the next tick"
            + ("" if ok else f"; FAILED: {failed}"),
            checks=x["checks"],
            details=x,
        )

    return run


# ----------------------------------------------------------------------------- maximal rates
def _max_rates_wp():
    """Infinite friction, prescribed runner: one sub-step per half period, i.e. the contact
    (80 or 128 cells wide) travels 100 or 6400 cells in a single sub-step."""

    def run():
        a = ex.working_point(0.7, 0.1, 2.5, resolution=40)
        b = ex.working_point(0.7, 0.1, 100.0, resolution=64)
        vals = [a["simulated"], b["simulated"]]
        ok = a["rel_error"] < 1e-3 and b["rel_error"] < 1e-3
        return _row(
            _finite(vals),
            float("nan"),
            True,
            f"working point vs Eq. 32 at 100 cells per sub-step: rel. error "
            f"{a['rel_error']:.1e}; at 6400 cells per sub-step (w = 100): "
            f"{b['rel_error']:.1e} (the kernel is exact within a sub-step here; "
            f"prescribed runner: no energy ledger)",
            ledger=False,
            checks={"rel. error < 1e-3": ok},
        )

    return run


def _max_rates_free(mu, r, ledger):
    """Free runner at one sub-step per half period (100 cells per sub-step) vs resolved."""
    eps = EPS_FRICTION if math.isfinite(mu) else EPS_STICK

    def run():
        kw = dict(mu=mu, periods=10, resolution=40)
        coarse = ex.simulate(BASE["delta"], eps, BASE["w"], r, n_sub=1, record=True, **kw)
        fine = ex.simulate(BASE["delta"], eps, BASE["w"], r, **kw)
        vc, vf = coarse["mean_v_star_over_omega_R"], fine["mean_v_star_over_omega_R"]
        finite = _finite(
            [vc, coarse["slip_work"], coarse["energy_residual"]], coarse["trajectory"].values()
        )
        rel, state_ok = _balance(coarse["energy"], 10, prescribed=False)
        off = (
            f"{abs(vc - vf) / abs(vf) * 100:.0f}% off"
            if vf
            else "identical"
            if vc == vf
            else f"{vc - vf:.2g} off"
        )
        accurate = abs(vc - vf) <= 0.05 * abs(vf) + 1e-12
        out = (
            f"v*/(omega R) {vc:.4g} at 1 sub-step vs {vf:.4g} at {fine['n_sub']} ({off}: "
            f"finite and bounded{'' if accurate else ', not accurate'})"
        )
        if not ledger:
            out += (
                "; energy ledger not checked at this step (the contact renews itself "
                "within the sub-step, and the ledger is exact only as the step shrinks; "
                "the state energy stays bounded)"
            )
        return _row(finite, rel, state_ok, out, ledger=ledger)

    return run


# ----------------------------------------------------------------------------- long run
def long_run(ticks=100_000, resolution=16):
    """``ticks`` control ticks (4 per half period) of a finite-mass, finite-friction drive at
    the default sub-steps through one ``Drive.run`` call."""
    wave = SquareWave(BASE["delta"], EPS_FRICTION, BASE["w"], GEO.a1, GEO.R, GEO.tau)
    m = ex.natural_frequency_mass(BASE["r"], wave, GEO.G_star)
    drv = Drive(
        DriveParams(GEO.R, GEO.E_star, GEO.G_star, mu=0.3, m=m),
        a_ref=GEO.a1,
        resolution=resolution,
        stroke=wave.stroke,
        a_max=GEO.a1,
        t_ref=GEO.tau,
    )
    drv.reset()
    tph = 4
    d, u, v = wave.ticks(max(ticks // (2 * tph), 1), tph)
    n_sub = ex.default_substeps(BASE["r"], wave, resolution, tph, 0.3)
    t = time.perf_counter()
    out = drv.run(dt_tick=wave.dt_tick(tph), n_sub=n_sub, omega_R=u, v=v, d=d)
    sec = time.perf_counter() - t
    n = d.size
    per = 2 * tph
    x = out["xstar"]
    k = (n // 10) // per * per  # a whole number of periods
    v_last = (x[-1] - x[-1 - k]) / (k * wave.dt_tick(tph)) / wave.omega_R
    v_mid = (x[n // 2 + k // 2] - x[n // 2 - k // 2]) / (k * wave.dt_tick(tph)) / wave.omega_R
    rel, state_ok = _balance(drv.energy, n / per, prescribed=False)
    return dict(
        finite=_finite([], out.values()),
        residual=rel,
        state_ok=state_ok,
        ticks=n,
        n_sub=n_sub,
        seconds=sec,
        v_last=v_last,
        v_mid=v_mid,
    )


def _long_case(ticks):
    def run():
        x = long_run(ticks)
        steady = abs(x["v_last"] - x["v_mid"]) <= 0.02 * abs(x["v_last"])
        return _row(
            x["finite"],
            x["residual"],
            x["state_ok"],
            f"{x['ticks']} ticks x {x['n_sub']} sub-steps in {x['seconds']:.2f} s "
            f"({x['seconds'] / x['ticks'] * 1e6:.0f} us per tick); mean v*/(omega R) "
            f"over the last 10% {x['v_last']:.4g}, around the middle {x['v_mid']:.4g} "
            f"(steady, no drift: {steady})",
            checks={"no drift": bool(steady)},
            details=x,
        )

    return run


# ----------------------------------------------------------------------------- sub-steps
def substep_sweep(n_subs=(1, 10, 100, 1000, 10000), resolution=16, periods=6):
    """Finite mass and friction from 1 to 1e4 sub-steps per half period: mean v*, energy."""
    vals, resid, state, finite = [], [], [], True
    for n in n_subs:
        r = ex.simulate(
            BASE["delta"],
            EPS_FRICTION,
            BASE["w"],
            BASE["r"],
            mu=0.3,
            periods=periods,
            resolution=resolution,
            n_sub=n,
            record=True,
        )
        vals.append(r["mean_v_star_over_omega_R"])
        rel, ok = _balance(r["energy"], periods, prescribed=False)
        resid.append(rel)
        state.append(ok)
        finite &= _finite([vals[-1], r["slip_work"]], r["trajectory"].values())
    diffs = np.abs(np.diff(vals))
    return dict(
        n_subs=list(n_subs),
        values=vals,
        residuals=resid,
        state_ok=state,
        finite=bool(finite),
        diffs=diffs.tolist(),
        shrinking=bool(np.all(diffs[1:] < diffs[:-1])),
        order=float(np.log10(diffs[-2] / diffs[-1])) if diffs.size >= 2 else float("nan"),
    )


def _substep_case(n_subs):
    def run():
        x = substep_sweep(n_subs)
        return _row(
            x["finite"],
            x["residuals"][-1],
            all(x["state_ok"]),
            "v*/(omega R) over sub-steps per half period "
            + ", ".join(f"{n}: {v:.6g}" for n, v in zip(x["n_subs"], x["values"]))
            + "; successive differences "
            + ", ".join(f"{d:.1e}" for d in x["diffs"])
            + f" shrink: {x['shrinking']} (order {x['order']:.2f} per decade); "
            "energy residual "
            + ", ".join(f"{r:.2g}" for r in x["residuals"])
            + " (ledger checked at the finest step only; the residual column shows it)",
            checks={"differences shrink": x["shrinking"]},
            details=x,
        )

    return run


# ----------------------------------------------------------------------------- env settings
ENV_SCENE = "default"
ENV_PERIODS = 32  # nominal periods of the square wave
ENV_RATIOS = (1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4, math.inf)
RESID_TOL_ENV = 1e-3  # env settings: energy created may not exceed 1e-3 of the work put in
ENV_CONTINUITY_FROM = 100.0  # |x* - x*_massless| non-increasing from this omega_n/Omega on ...
ENV_CONTINUITY_TOL = 0.1  # ... and below this many scene tolerances at the largest ratio
ENV_STEP_TOL_ABS = 0.01  # env step check: change of x* at 4x sub-steps, in scene tolerances


def env_mass(scene, r: float) -> float:
    """Runner mass [kg] for omega_n/Omega = r on a scene: omega_n = sqrt(2 a_max G*/m) with
    a_max the contact radius at N_max, Omega = 2 pi / period; r = inf is massless."""
    if math.isinf(r):
        return 0.0
    a = scenes.contact_radius_max(scene)
    return 2 * a * scene.G_star / (r * 2 * math.pi / scene.period) ** 2


def env_square_wave(scene, periods: int):
    """(N, omega R, v) per tick: forth N = 0.8 N_max, omega R = +0.7 omega_R_max; back N = 0.4
    N_max, -0.7 omega_R_max; v = omega R (1 - 0.3 creep_max); ticks_per_period/2 ticks each."""
    tpp = scene.ticks_per_period
    k = np.arange(periods * tpp)
    forth = (k % tpp) < tpp // 2
    N = np.where(forth, 0.8, 0.4) * scene.N_max
    u = np.where(forth, 1.0, -1.0) * 0.7 * scene.omega_R_max
    return N, u, u * (1 - 0.3 * scene.creep_max)


def env_run(
    r: float, scene_name: str = ENV_SCENE, periods: int = ENV_PERIODS, sub_factor: int = 1
) -> dict:
    """The square wave ``env_square_wave`` on a scene whose runner mass gives omega_n/Omega =
    r, at the scene's own tick and sub-steps (``Scene.n_sub``, "auto" on the default scene;
    times ``sub_factor``), through a drive built as the env builds it (``env.build_drive``:
    grid over +-stroke_roll, a_ref = a_max, the scene's resolution, t_ref = period) but with
    the energy ledger.  Energies are per period in 2 G* a_max^3, x* in scene tolerances."""
    base = scenes.load_scene(scene_name)
    m = env_mass(base, r)
    sc = base.replace(runner_mass=m)
    a = scenes.contact_radius_max(sc)
    params = DriveParams(sc.R, sc.E_star, sc.G_star, mu=sc.mu, m=sc.runner_mass, F_ext=sc.F_ext)
    drv = Drive(
        params,
        a_ref=a,
        resolution=sc.resolution,
        stroke=(-sc.stroke_roll, sc.stroke_roll),
        a_max=a,
        t_ref=sc.period,
        ledger=True,
    )
    drv.reset()
    N, u, v = env_square_wave(sc, periods)
    n_sub = sc.n_sub * sub_factor
    t = time.perf_counter()
    out = drv.run(dt_tick=sc.dt, n_sub=n_sub, omega_R=u, v=v, N=N)
    sec = time.perf_counter() - t
    e = drv.energy
    unit = 2 * sc.G_star * a**3 * periods  # [J]
    floor = FLOOR * unit
    supply = e["drive"] + e["ext"] + e["kinetic_start"]
    return dict(
        r=r,
        mass=m,
        n_sub=n_sub,
        seconds=sec,
        finite=_finite([], out.values()),
        residual=float(e["residual"] / max(e["work_in"], floor)),
        floored=bool(e["work_in"] < floor),
        state_ok=bool(e["elastic"] + e["kinetic"] <= supply + floor),
        energy={k: float(x / unit) for k, x in e.items()},
        x=float(out["xstar"][-1] / sc.tolerance),
        runner_steps=(math.inf if m == 0 else n_sub * sc.ticks_per_period / r),
        # the wavelength 2 pi omega R / omega_n of the runner's ringing on the contact
        ringing_cells=(
            0.7 * sc.omega_R_max * sc.period / r / (a / sc.resolution) if m > 0 else 0.0
        ),
        tolerance=sc.tolerance,
        scene=sc.name,
    )


class _EnvSweep:
    """``env_run`` for each ratio (and sub-step factor), run once and shared by the cases."""

    def __init__(self, scene_name=ENV_SCENE, periods=ENV_PERIODS):
        self.scene_name, self.periods, self.rows = scene_name, periods, {}

    def __call__(self, r, sub_factor=1):
        if (r, sub_factor) not in self.rows:
            self.rows[r, sub_factor] = env_run(r, self.scene_name, self.periods, sub_factor)
        return self.rows[r, sub_factor]


_LEDGER_TERMS = ("drive", "ext", "elastic", "release", "slip", "snap", "kinetic")


def _env_case(sweep: _EnvSweep, r, step_check=True):
    """One ratio at the scene's sub-steps; with ``step_check`` also at 4x the sub-steps (the
    change of x* and of the residual, and the ledger term that changed most)."""

    def run():
        x = sweep(r)
        ml = sweep(math.inf)
        S = x["runner_steps"]
        parts = [
            f"m = {x['mass']:.3g} kg, {x['n_sub']} sub-steps per tick"
            + ("" if math.isinf(S) else f" ({S:.3g} per runner period)")
            + f"; x* after {sweep.periods} periods {x['x']:.4g} tolerances"
        ]
        if math.isinf(r):
            parts.append("massless runner: force equilibrium, follows the sphere")
        else:
            parts.append(f"{abs(x['x'] - ml['x']):.3g} tolerances from the massless runner's")
        e = x["energy"]
        parts.append(
            f"work put in {e['work_in']:.3g} x 2 G* a_max^3 per period"
            + (
                f" (below the round-off floor {FLOOR:g}: the residual is relative to the floor)"
                if x["floored"]
                else ""
            )
            + f", slip work {e['slip']:.3g}"
        )
        if not math.isinf(S):
            q = (2 * math.pi / S) ** 2 / _K.THETA2_BLEND
            lam = 1.0 / (1.0 + q**4)
            if lam < 0.99:
                parts.append(
                    f"runner period resolved by only {S:.3g} sub-steps (omega_n dt = "
                    f"{2 * math.pi / S:.2g} at N_max): the runner step is "
                    f"{1 - lam:.0%} backward Euler (the kernel's blend), which "
                    "damps the ringing and tends to the massless limit"
                )
        step, conv = "-", None
        if step_check:
            x4 = sweep(r, 4)
            dx = abs(x4["x"] - x["x"])
            conv = bool(dx <= max(STEP_TOL_REL * abs(x4["x"]), ENV_STEP_TOL_ABS))
            step = f"x* {dx:.1e} tol., residual {x4['residual']:.2g} at 4x" + (
                "" if conv else " NOT converged"
            )
            if x["residual"] <= -RESID_TOL_ENV:
                e4 = x4["energy"]
                w = e["work_in"]
                w4 = e4["work_in"]
                k = max(_LEDGER_TERMS, key=lambda t: abs(e[t] / w - e4[t] / w4))
                parts.append(
                    f"energy created beyond {RESID_TOL_ENV:g} of the work put in; at "
                    f"4x the sub-steps the residual is {x4['residual']:+.2g}, and the "
                    f"ledger term that changes most is the {k} work: {e[k] / w:.4g} of "
                    f"the work put in, {e4[k] / w4:.4g} at 4x"
                    + (
                        ": the slip work, second order in the sub-step, is overbooked at "
                        "the scene's sub-steps"
                        if k == "slip" and e[k] / w > e4[k] / w4
                        else ""
                    )
                )
            elif x["residual"] > 0.1 and abs(x4["residual"] - x["residual"]) < (
                0.1 * x["residual"]
            ):
                parts.append(
                    f"residual {x['residual']:.2g}, the same at 4x the sub-steps: "
                    "the uniform cells average out the runner's ringing imprinted on "
                    f"the stuck contact (its wavelength {x['ringing_cells']:.2g} "
                    "cells), not the step"
                )
        return _row(
            x["finite"],
            x["residual"],
            x["state_ok"],
            "; ".join(parts),
            step=step,
            converged=conv,
            details=x,
            resid_tol=RESID_TOL_ENV,
        )

    return run


def _env_continuity_case(sweep: _EnvSweep, ratios):
    """|x* - x*_massless| non-increasing from ``ENV_CONTINUITY_FROM`` on, below
    ``ENV_CONTINUITY_TOL`` tolerances at the largest finite ratio."""

    def run():
        rs = [r for r in ratios if ENV_CONTINUITY_FROM <= r < math.inf]
        ml = sweep(math.inf)["x"]
        d = [abs(sweep(r)["x"] - ml) for r in rs]
        mono = all(b <= a * (1 + 1e-9) + 1e-12 for a, b in zip(d, d[1:]))
        close = d[-1] < ENV_CONTINUITY_TOL
        checks = {
            f"non-increasing from omega_n/Omega = {ENV_CONTINUITY_FROM:g} on": mono,
            f"below {ENV_CONTINUITY_TOL:g} tolerance at {rs[-1]:g}": close,
        }
        return _row(
            True,
            float("nan"),
            True,
            "|x* - x*_massless| in scene tolerances at omega_n/Omega = "
            + ", ".join(f"{r:g}: {x:.3g}" for r, x in zip(rs, d))
            + f"; non-increasing: {mono}; below {ENV_CONTINUITY_TOL:g} at {rs[-1]:g}: "
            f"{close} (the runs of the cases above)",
            ledger=False,
            checks=checks,
            details=dict(ratios=rs, dist=d),
        )

    return run


# ----------------------------------------------------------------------------- the grid
def cases(quick=False):
    """(name, callable) pairs; ``quick``: the fastest subset (used by the tests)."""
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
    c.append(
        ("lift-off mid-step (N = 0 for one tick), mu = 0.3, free runner", _liftoff_case(0.3, r))
    )
    c.append(
        (
            "lift-off mid-step (N = 0 for one tick), mu = inf, prescribed runner",
            _liftoff_case(math.inf, 0.0),
        )
    )
    c.append(("maximal rates: 100 and 6400 cells per sub-step, working point", _max_rates_wp()))
    c.append(
        (
            "maximal rates: 100 cells per sub-step, free runner, mu = inf",
            _max_rates_free(math.inf, r, ledger=True),
        )
    )
    c.append(
        (
            "maximal rates: 100 cells per sub-step, free runner, mu = 0.3",
            _max_rates_free(0.3, r, ledger=False),
        )
    )
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
    sweep = _EnvSweep()
    env_rs = [1.0, 100.0, 1e3, 1e4, math.inf] if quick else list(ENV_RATIOS)
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
