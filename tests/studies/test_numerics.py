"""Numerical quality: the fast cases of the stability grid, the work-precision study (its
``--quick`` path through the CLI) and the zero lines of the paper figures.

Tolerances, tiered: 1e-4 (in omega R) for zero lines that are exact in the continuum and
grid-limited at 32 springs per a1 (measured ~1e-5); 1% of the work put in for the energy ledger
(``stability_checks.RESID_TOL``); exact zeros for released springs (the kernel sets them to 0.0).
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from rolling_env.cli.main import main
from rolling_env.physics import analytic
from rolling_env.physics import experiments as ex
from rolling_env.studies import converge, figures, stability, stability_cases


@pytest.fixture(scope="module")
def stability_rows():
    return stability.run(quick=True)


# ----------------------------------------------------------------------------- stability
def test_quick_stability_grid_passes(stability_rows):
    """Every quick case: finite, energy not created beyond 1% of the work put in (1e-3 at env
    settings), state energy bounded, run time < 60 s, its own checks (lift-off, convergence
    in the step, the env runner's approach to the massless limit)."""
    bad = [(r["case"], r["outcome"]) for r in stability_rows if r["status"] != "PASS"]
    assert not bad, f"failed stability cases: {bad}"


def test_all_outputs_finite(stability_rows):
    bad = [r["case"] for r in stability_rows if not r["finite"]]
    assert not bad, f"non-finite outputs (or an exception) in: {bad}"


def test_energy_never_created(stability_rows):
    """Ledger residual > -1% of the work put in where it is checked (-1e-3 for the cases at
    env settings, ``stability_env.RESID_TOL_ENV``); the state energy (elastic + kinetic) never
    exceeds the work put in, at any step."""
    for r in stability_rows:
        assert r["state_ok"], f"{r['case']}: state energy exceeds the work put in"
        if r["ledger"] and math.isfinite(r["residual"]):
            assert r["residual"] > -r["resid_tol"], (
                f"{r['case']}: energy residual {r['residual']:.3g} < -{r['resid_tol']} "
                "(energy created)"
            )


def test_env_runner_tends_to_the_massless_limit(stability_rows):
    """At env settings (default scene, square wave): the final x* of ever lighter runners
    approaches the massless runner's, monotonically from omega_n/Omega = 100 on, within 0.1
    scene tolerance at 1e4 (measured 8e-7)."""
    row = next(r for r in stability_rows if "tends to the massless" in r["case"])
    d = row["details"]["dist"]
    assert all(b <= a for a, b in zip(d, d[1:])) and d[-1] < 0.1, d


@pytest.mark.parametrize("mu,r", [(0.3, 0.3), (math.inf, 0.0), (0.3, math.inf)])
def test_liftoff_releases_every_spring(mu, r):
    """N = 0 for one tick in the middle of a forth step: every cell content exactly 0, T = 0,
    N = 0 (tolerance: exact), and the contact re-forms on the next tick."""
    x = stability_cases.liftoff(mu, r)
    assert x["U_max"] == 0.0, f"max |U| = {x['U_max']} after lift-off (must be exactly 0)"
    failed = [k for k, v in x["checks"].items() if not v]
    assert not failed, f"lift-off checks failed (mu {mu}, r {r}): {failed}"
    assert x["finite"], "non-finite output around the lift-off"
    assert x["residual"] > -stability.RESID_TOL, f"energy residual {x['residual']:.3g}"


def test_long_run_stays_finite_and_steady():
    """2e4 ticks through one Drive.run call: finite, energy not created, no drift of the mean
    runner velocity (last 10% vs middle, 2%)."""
    x = stability_cases.long_run(20_000)
    assert x["finite"], "non-finite output in a 2e4-tick run"
    assert x["state_ok"], "state energy exceeds the work put in"
    assert x["residual"] > -stability.RESID_TOL, f"energy residual {x['residual']:.3g}"
    assert abs(x["v_last"] - x["v_mid"]) <= 0.02 * abs(x["v_last"]), (
        f"mean v* drifts: last 10% {x['v_last']:.5g}, middle {x['v_mid']:.5g}"
    )


def test_substep_refinement_converges():
    """1 .. 1000 sub-steps per half period: successive differences of the mean runner velocity
    strictly decrease; the ledger closes to 1% at the finest step."""
    x = stability_cases.substep_sweep((1, 10, 100, 1000))
    d = x["diffs"]
    assert all(b < a for a, b in zip(d, d[1:])), f"differences do not shrink: {d}"
    assert x["residuals"][-1] > -stability.RESID_TOL, f"residuals {x['residuals']}"
    assert all(x["state_ok"]), "state energy exceeds the work put in at some step"


def test_dynamic_run_converges_in_dt_at_second_order():
    """Finite mass and friction (the converge study's ``DYN`` case, 6 periods, 32 cells per
    a1): the mean runner velocity and the slip work at 20 to 640 sub-steps per half period
    against a run at 16x the finest.  Observed order in the sub-step in [1.5, 2.5] for both
    (measured 1.84 and 1.73; the exact runner step and the trapezoid wear, docs/numerics.md),
    and the slip work's last difference ratio above 3.4 (measured 3.76: it approaches 4, the
    coarse steps cross several cells per sub-step)."""
    d, ns = converge.DYN, (20, 40, 80, 160, 320, 640)
    runs = [
        ex.simulate(
            d["delta"],
            d["eps"],
            d["w"],
            d["omega_n_ratio"],
            mu=d["mu"],
            periods=6,
            resolution=32,
            n_sub=n,
        )
        for n in ns + (16 * ns[-1],)
    ]
    for key in ("mean_v_star_over_omega_R", "slip_work"):
        vals = np.array([r[key] for r in runs])
        errs = np.abs(vals[:-1] - vals[-1])
        p = converge.order(ns, errs)
        assert 1.5 < p < 2.5, f"{key}: observed order in dt {p:.2f} (errors {errs})"
        if key == "slip_work":
            assert errs[-2] / errs[-1] > 3.4, f"slip work: last error ratio {errs[-2:]}"


def test_default_substeps_converge_the_stiff_runner():
    """omega_n/Omega = 2 (the worst measured case of ``default_substeps``, infinite friction,
    40 periods): the default is within its stated tolerance (1% or 1e-3 x Eq. 32, the larger)
    of the converged mean velocity.  The error is second order in the step, so the default's
    error is 16/15 of its distance to a run at 4x the sub-steps (measured 1.3e-5 omega R,
    0.15 of the tolerance)."""
    a = ex.simulate(0.7, 0.1, 2.5, 2.0, periods=40)
    b = ex.simulate(0.7, 0.1, 2.5, 2.0, periods=40, n_sub=4 * a["n_sub"])
    va, vb = a["mean_v_star_over_omega_R"], b["mean_v_star_over_omega_R"]
    assert a["step_converged"] and b["step_converged"]
    tol = max(ex.STEP_TOL_REL * abs(vb), ex.STEP_TOL_EQ32 * analytic.eq32(0.7, 0.1, 2.5))
    assert 16 / 15 * abs(va - vb) <= 0.5 * tol, f"default {va} vs 4x {vb}"


def test_default_substeps_keep_the_slip_work():
    """Finite friction (mu 0.3) where the trailing-edge slip zone spans about a cell (eps
    0.9998 at 64 cells per a1, the worst measured width): the default's slip work is within
    1% of a run at 8x the sub-steps (measured 0.1%; 1 cell per sub-step is 3% high)."""
    a = ex.simulate(0.7, 0.9998, 2.5, 0.0, mu=0.3, periods=3)
    b = ex.simulate(0.7, 0.9998, 2.5, 0.0, mu=0.3, periods=3, n_sub=8 * a["n_sub"])
    assert abs(a["slip_work"] / b["slip_work"] - 1) < 1e-2, (a["slip_work"], b["slip_work"])


def test_unresolved_runner_period_is_reported():
    """A run whose runner period gets fewer sub-steps than the default asks for says so:
    a coarse ``n_sub``, the cap above omega_n/Omega = 100, no resolution above 1000."""
    coarse = ex.simulate(0.7, 0.1, 2.5, 3.0, periods=2, n_sub=160)
    assert not coarse["step_converged"] and "not guaranteed converged" in coarse["step_note"]
    assert coarse["runner_steps_per_period"] == pytest.approx(160 * 2 / 3)
    for r, word in ((200.0, "capped"), (2e3, "massless")):
        res = ex.simulate(0.7, 0.1, 2.5, r, periods=2)
        assert not res["step_converged"] and word in res["step_note"], res["step_note"]
    for r in (0.0, 0.3, 20.0, 100.0, math.inf):
        res = ex.simulate(0.7, 0.1, 2.5, r, periods=2)
        assert res["step_converged"] and res["step_note"] == "", (r, res["step_note"])


def test_energy_ledger_closes_in_full_sliding():
    """Full sliding (mu = 1e-4, eps = 0.1): the released energy of sliding edge cells is booked
    at the friction limit, so the ledger closes to 1% at the default sub-steps."""
    res = ex.simulate(0.7, 0.1, 2.5, 0.3, mu=1e-4, periods=20)
    assert res["energy_residual"] > -stability.RESID_TOL, (
        f"energy residual {res['energy_residual']:.3g} in full sliding"
    )


# ----------------------------------------------------------------------------- work-precision
def test_working_point_error_envelope_falls_at_second_order():
    """Worst case over 4 grid alignments falls monotonically; observed order in [1.6, 2.6]."""
    case = (0.7, 0.1, 2.5)
    ref = analytic.eq32(*case)
    res = [8, 16, 32, 64, 128]
    errs = [
        max(
            abs(ex.working_point(*case, resolution=r, grid_offset=o)["simulated"] - ref)
            for o in np.arange(4) / 4
        )
        / ref
        for r in res
    ]
    assert all(b < a for a, b in zip(errs, errs[1:])), f"not monotone: {errs}"
    p = converge.order(res, errs)
    assert 1.6 < p < 2.6, f"observed order {p:.2f} (errors {errs})"


@pytest.fixture(scope="module")
def quick_study(tmp_path_factory):
    """``rolling-drive converge --quick`` run once: its output folder."""
    out = tmp_path_factory.mktemp("converge_quick")
    assert main(["converge", "--quick", "--out", str(out)]) == 0
    return out


def test_converge_quick_csv(quick_study):
    """``rolling-drive converge --quick`` writes a CSV whose working-point error falls
    monotonically from 8 to 128 springs per a1, each doubling by at least a factor 0.6
    (second order gives 0.25), with observed order in [1.5, 2.5]; and a PNG."""
    path = quick_study / "work_precision_quick.csv"
    assert path.exists() and (quick_study / "work_precision_quick.png").exists(), (
        "converge --quick did not write its CSV and PNG"
    )
    rows = list(csv.DictReader(path.open()))
    q = f"wp:{converge.WP_CASES[0]}"
    sel = sorted(
        (
            (float(r["value"]), float(r["error"]), float(r["observed_order"]))
            for r in rows
            if r["quantity"] == q and 8 <= float(r["value"]) <= 128
        )
    )
    assert [s[0] for s in sel] == [8, 16, 32, 64, 128], f"resolutions in the CSV: {sel}"
    errs = [s[1] for s in sel]
    ratios = [b / a for a, b in zip(errs, errs[1:])]
    assert all(x <= 0.6 for x in ratios), (
        f"working-point error not falling monotonically (tolerance: factor <= 0.6 per "
        f"doubling): errors {errs}, ratios {ratios}"
    )
    assert 1.5 <= sel[0][2] <= 2.5, f"observed order {sel[0][2]} outside [1.5, 2.5]"
    naive = [r for r in rows if r["quantity"].startswith("naive:")]
    assert naive, "the naive reference row is missing from the CSV"


def test_converge_quick_env_lines(quick_study):
    """The quick study's env lines (the default scene; ``converge.ENV_QUICK_SCENES``): the
    accuracy module's standard episodes replayed at the shipped sub-steps x 1/4 .. 4.  At the
    shipped sub-steps the worst error equals ``rolling_env.studies.accuracy``'s (same episodes, same
    reference; relative 1e-9).  The slip work, charged from the onset of sliding within each
    sub-step, is at the grid's floor from 1/4x the sub-steps on: within 1% at every level
    (measured 0.70% at 1/4x, 0.49% at 1x) and changed by less than 0.1% of the reference
    from 1x to 4x (measured 0.008%); charged the limit's mean over the whole sub-step it was
    6% off at 1/4x.  The x* error at the shipped grid is the grid's own: 2x and 4x the
    sub-steps change it by less than 10% (measured 0.085 tolerances at all three)."""
    import rolling_env
    from rolling_env.studies import accuracy

    assert converge.ENV_QUICK_SCENES == ("default",)
    rows = list(csv.DictReader((quick_study / "work_precision_quick.csv").open()))
    s0 = rolling_env.make("default").unwrapped.scene.n_sub
    want = [max(1, round(s0 * f)) for f in converge.ENV_SUB_FACTORS]
    lines = {}
    for q in ("env_x:default", "env_slip:default"):
        sel = [r for r in rows if r["quantity"] == q]
        assert all(r["refine"] == "sub_steps" for r in sel), sel
        assert [int(float(r["value"])) for r in sel] == want, f"{q}: sub-steps {sel}"
        assert all(0.0 < float(r["seconds"]) < 1e-2 for r in sel), f"{q}: times {sel}"
        lines[q] = {int(float(r["value"])): float(r["error"]) for r in sel}
    assert not any(
        r["quantity"].startswith("env_") and ":default" not in r["quantity"] for r in rows
    ), "quick study has env lines of other scenes"
    # the episodes the env lines replay (converge.env_episodes): Eq. 32 and one random
    acc = accuracy.scene_accuracy(
        "default", timing_repeats=1, episodes_bang_bang=0, episodes_constant=0
    )
    kinds = [e["kind"] for e in acc["episodes"]]
    assert kinds == ["eq32-feedback", "eq32-open-loop", "random"], kinds
    x_acc = max(e["xstar_error_tol"] for e in acc["episodes"])
    s_acc = max(abs(e["slip_error_pct"]) for e in acc["episodes"]) / 100.0
    assert lines["env_x:default"][s0] == pytest.approx(x_acc, rel=1e-9)
    assert lines["env_slip:default"][s0] == pytest.approx(s_acc, rel=1e-9)
    slip, x = lines["env_slip:default"], lines["env_x:default"]
    assert max(slip.values()) < 0.01, f"slip work error vs sub-steps: {slip}"
    assert abs(slip[want[-1]] - slip[s0]) < 1e-3, f"slip work error vs sub-steps: {slip}"
    assert all(abs(x[n] / x[s0] - 1.0) < 0.1 for n in want[3:]), f"x* error: {x}"


def test_converge_env_rows_infinite_friction_and_grid_line():
    """``converge.env_rows`` on heavy_inf_friction: x* lines only (no slip work with infinite
    friction); the sub-steps-and-grid line's factor-1 point is the sub-step line's shipped
    point; the shipped settings are within 0.1 tolerance and the worst x* error falls as
    both are refined, irregularly (the infinite-friction grid error of the random episode),
    at least tenfold from half to four times the shipped settings."""
    rows = converge.env_rows("heavy_inf_friction", repeats=1)
    qs = {r["quantity"] for r in rows}
    assert qs == {"env_x:heavy_inf_friction", "env_x_grid:heavy_inf_friction"}, qs
    shipped = [r for r in rows if r["shipped"]]
    assert len(shipped) == 2 and shipped[0]["error"] == shipped[1]["error"], shipped
    grid = {r["value"]: r["error"] for r in rows if r["refine"] == "sub_steps+grid"}
    assert sorted(grid) == sorted(converge.ENV_BOTH_FACTORS)
    assert grid[1] < 0.1, f"shipped settings beyond 0.1 tolerance: {grid}"
    assert grid[4] < grid[2] < grid[1] and grid[4] < 0.1 * grid[0.5], (
        f"x* error does not fall with the grid: {grid}"
    )


# ----------------------------------------------------------------------------- figures
def test_figure_zero_lines_match_eq29_and_eq32():
    """Figs. 6 and 8 (delta 0.93, w 2.2, 32 springs per a1): the simulated zero line of the
    force sum is Eq. 29 and that of the period impulse is Eq. 32, within 1e-4 omega R."""
    eps = np.array([0.0, 0.3, 0.6, 0.9])
    zfs, zimp = figures.zero_lines(eps, resolution=32)
    d6 = np.max(np.abs(zfs - analytic.eq29(figures.FIG_DELTA, eps)))
    d8 = np.max(np.abs(zimp - analytic.eq32(figures.FIG_DELTA, eps, figures.FIG_W)))
    assert d6 < 1e-4, f"Fig. 6 zero line deviates from Eq. 29 by {d6:.2e} (tolerance 1e-4)"
    assert d8 < 1e-4, f"Fig. 8 zero line deviates from Eq. 32 by {d8:.2e} (tolerance 1e-4)"


def test_fig9_markers_match_eq32():
    rows = figures.fig9_points([0.0, 0.5], resolution=64)
    dev = max(abs(r[3] - r[4]) for r in rows)
    assert dev < 1e-4, f"Fig. 9 working points deviate from Eq. 32 by {dev:.2e} (tol. 1e-4)"


def _env_episode(scene, sub_steps, acts):
    """Slip work [J] and final x* [m] of the env driven by ``acts`` at ``sub_steps``."""
    import rolling_env

    env = rolling_env.make(scene, sub_steps=sub_steps)
    env.reset(seed=0)
    slip = 0.0
    for a in acts:
        _, _, _, _, info = env.step(a)
        slip += info["slip_work"]
    return slip, info["xstar"]


def test_env_slip_work_converges_second_order_in_the_sub_step():
    """The episode's slip work (the wear term) at 16, 32, 64 and 128 sub-steps per tick on
    the default scene (128 random ticks): the differences of successive runs shrink about
    4x per halving of the step (second order; measured ratios 3.6-4.1), none below 3.0 and
    their geometric mean above 3.5."""
    acts = np.random.default_rng(3).uniform(-1, 1, (128, 3)).astype(np.float32)
    slips = np.array([_env_episode("default", n, acts)[0] for n in (16, 32, 64, 128)])
    d = np.diff(slips)
    ratios = d[:-1] / d[1:]
    assert np.all(ratios > 3.0) and np.exp(np.mean(np.log(ratios))) > 3.5, (
        f"slip work not second order in the sub-step: difference ratios {ratios}"
    )


def test_runner_position_converges_second_order_where_resolved():
    """A free runner near resonance (omega_n/Omega = 2, infinite friction, 6 square-wave
    periods, 16 cells per a1): its mean velocity at 16, 32, 64 and 128 sub-steps per half
    period (8-64 per runner period); the differences of successive runs shrink by 3.3x or
    more per halving of the step (second order; measured 3.5-4.1)."""
    v = np.array(
        [
            ex.simulate(0.7, 0.1, 2.5, 2.0, periods=6, resolution=16, n_sub=n)[
                "mean_v_star_over_omega_R"
            ]
            for n in (16, 32, 64, 128)
        ]
    )
    d = np.diff(v)
    ratios = d[:-1] / d[1:]
    assert np.all(ratios > 3.3), f"x* not second order in the sub-step: ratios {ratios}"
