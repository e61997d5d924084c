"""The stability cases of ``simulate``'s kernel: free runners from omega_n/Omega = 1e-3 to
massless over friction from 1e-4 to inf, lift-off mid-step, maximal rates, a long run and
sub-steps from 1 to 1e4 per half period."""

from __future__ import annotations

import math
import time

import numpy as np

from rolling_env.physics import analytic
from rolling_env.physics import experiments as ex
from rolling_env.physics.excitation import SquareWave
from rolling_env.physics.model import Drive, DriveParams
from rolling_env.studies.stability_checks import (
    BASE,
    EPS_FRICTION,
    EPS_STICK,
    GEO,
    _balance,
    _eq_ref,
    _finite,
    _row,
    _step_check,
)

# ----------------------------------------------------------------------------- free runner


def _geo_drive(mu, m, resolution, wave) -> Drive:
    """A drive of the cases' geometry (``GEO``) over the square wave's stroke."""
    return Drive(
        DriveParams(GEO.R, GEO.E_star, GEO.G_star, mu=mu, m=m),
        a_ref=GEO.a1,
        resolution=resolution,
        stroke=wave.stroke,
        a_max=GEO.a1,
        t_ref=GEO.tau,
    )


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
        ref = _eq_ref(delta, eps, w)
        parts = _motion_notes(res, (delta, eps, w), r, mu, periods, ref, quasi_static)
        parts += _runner_notes(res, r, ref)
        if rel > 0.1:
            parts.append(_dissipation_note(res, res4["energy_residual"], rel, w, r))
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


def _motion_notes(res, square_wave, r, mu, periods, ref, quasi_static) -> list:
    """The mean runner velocity against its reference ``ref`` ((value, name)), the slip work
    and stuck fraction with friction, the quasi-static working point where asked, and why the
    run is not at steady state where it is not."""
    delta, eps, w = square_wave
    v = res["mean_v_star_over_omega_R"]
    tr = res["trajectory"]
    parts = [f"v*/(omega R) {v:.4g}"]
    if ref[0] is not None:
        parts[0] += f" ({ref[1]} {ref[0]:.4g})"
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
    return parts


def _runner_notes(res, r, ref) -> list:
    """What the runner's mass makes of the result: massless, its period under-resolved,
    stiff, or in the resonant band (``ref``: the reference (value, name))."""
    v = res["mean_v_star_over_omega_R"]
    if math.isinf(r):
        return ["massless runner: force equilibrium, follows the sphere, no net motion"]
    if not res["step_converged"]:
        nrp = res["runner_steps_per_period"]
        if r > ex.RUNNER_CAPPED_MAX:
            return [
                f"runner period not resolved ({nrp:.2g} sub-steps per runner "
                f"period; the default resolves omega_n/Omega <= "
                f"{ex.RUNNER_CAPPED_MAX:g}): the runner step blends into backward "
                "Euler and gives the massless limit, runner follows the sphere"
            ]
        return [
            f"runner period resolved by only {nrp:.3g} sub-steps (the "
            f"default caps them above omega_n/Omega = "
            f"{ex.RUNNER_RESOLVED_MAX:g}): mean v* not guaranteed converged "
            "in the step"
        ]
    if r >= 2 and ref[0] is not None:
        return [f"stiff runner: {v / ref[0]:.2g} x {ref[1]}"]
    if ref[0] is not None and 0.5 <= r <= 2 and v > ref[0]:
        return ["resonant band: above the quasi-static value"]
    return []


def _dissipation_note(res, rel4, rel, w, r) -> str:
    """Why a share ``rel`` (over 10%) of the work put in is dissipated by the numerics
    (``rel4``: the share at 4x the sub-steps)."""
    if res["runner_steps_per_period"] < math.pi:
        return (
            f"{rel:.0%} of the work put in is dissipated by the numerics: the "
            "runner period is not resolved (omega_n dt > 2), and the runner "
            "step's blend into backward Euler damps the runner's ringing"
        )
    if abs(rel4 - rel) <= 0.1 * rel:
        wl = 2 * w * ex.DEFAULT_RESOLUTION / r  # 2 pi omega R / omega_n, in cells
        return (
            f"{rel:.0%} of the work put in is dissipated by the numerics, "
            f"the same at 4x the sub-steps ({rel4:.0%}): the uniform cells "
            "average out the runner's ringing imprinted on the stuck contact "
            f"(its wavelength 2 pi omega R / omega_n is {wl:.2g} cells), "
            "large against the little work a runner this light draws"
        )
    return (
        f"{rel:.0%} of the work put in is dissipated by the numerics "
        f"({rel4:.0%} at 4x the sub-steps)"
    )


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
    drv = _geo_drive(mu, m, resolution, wave)
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
    drv = _geo_drive(0.3, m, resolution, wave)
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
