"""Subcommands of the physics core: working-point, simulate, mindlin."""

from __future__ import annotations

import math

from rolling_env.cli.main import checked_float, emit, finite_float, positive_int
from rolling_env.physics import experiments as ex
from rolling_env.physics.mindlin import MINDLIN_MU_MAX, MINDLIN_POINTS_MAX, mindlin


def register(sub):
    _register_working_point(sub)
    _register_simulate(sub)
    _register_mindlin(sub)


def _register_working_point(sub):
    p = sub.add_parser(
        "working-point",
        help="quasi-static working point vs Eq. 32 (infinite runner mass and friction)",
        description="Simulate to periodic steady state with a prescribed runner "
        "and find v*/(omega R) where the period impulse vanishes (Eq. 31).",
    )
    _dimensionless(p)
    p.add_argument(
        "--resolution",
        type=finite_float("resolution", 2, 1e5),
        default=ex.DEFAULT_RESOLUTION,
        help="springs per contact radius a1 "
        f"(default {ex.DEFAULT_RESOLUTION:g}: below 0.1%% error where the back-step "
        "contact edge is resolved, see docs/physics.md)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_working_point)


def _register_simulate(sub):
    p = sub.add_parser(
        "simulate",
        help="square-wave excitation driving a runner of finite mass",
        description="The paper's square wave driving a free runner; r = omega_n/"
        "Omega with omega_n = sqrt(2 a1 G*/m), Omega = 2 pi/tau (0: infinite "
        "mass, inf: massless).",
    )
    _dimensionless(p)
    p.add_argument(
        "--omega-n-ratio",
        required=True,
        type=checked_float("omega-n-ratio", lambda n, x: ex.check_omega_n_ratio(x, n)),
        help="r = omega_n / Omega: 0 (infinitely heavy), inf (massless) or in "
        f"[{ex.OMEGA_N_RATIO_RANGE[0]:g}, {ex.OMEGA_N_RATIO_RANGE[1]:g}]",
    )
    p.add_argument(
        "--mu",
        type=finite_float("mu", 0, math.inf, lo_open=True, allow_inf=True),
        default=math.inf,
        help="friction coefficient (default inf: no slip)",
    )
    p.add_argument(
        "--a-over-r",
        type=finite_float("a-over-r", *ex.A_OVER_R_RANGE),
        default=0.02,
        help="a1/R (matters with finite friction; default 0.02)",
    )
    p.add_argument(
        "--g-over-e",
        type=finite_float("g-over-e", 0, 10, lo_open=True),
        default=ex.Geometry().g_over_e,
        help="G*/E* (default 0.824, nu = 0.3)",
    )
    p.add_argument(
        "--periods",
        type=positive_int("periods", 2, ex.MAX_TICKS // 2),
        default=40,
        help="excitation periods to simulate (default 40; the mean runner velocity "
        "is taken over the second half)",
    )
    p.add_argument(
        "--resolution",
        type=finite_float("resolution", 2, 1e5),
        default=ex.DEFAULT_RESOLUTION,
        help="springs per contact radius a1",
    )
    p.add_argument(
        "--n-sub",
        type=positive_int("n-sub"),
        default=None,
        help="sub-steps per half period (default: resolve runner and grid)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_simulate)


def _register_mindlin(sub):
    p = sub.add_parser(
        "mindlin",
        help="Cattaneo-Mindlin tangential loading vs the analytic law",
        description="Press the sphere, then displace it tangentially with the "
        "runner held and no rolling; compare T/(mu N) with the Cattaneo-Mindlin law.",
    )
    p.add_argument(
        "--mu",
        type=finite_float("mu", 0, MINDLIN_MU_MAX, lo_open=True),
        required=True,
        help="friction coefficient",
    )
    p.add_argument(
        "--points",
        type=positive_int("points", 2, MINDLIN_POINTS_MAX),
        default=21,
        help="tangential displacements compared, up to 1.2 u* (full sliding; default 21)",
    )
    p.add_argument(
        "--resolution",
        type=finite_float("resolution", 2, 1e5),
        default=ex.DEFAULT_RESOLUTION,
        help=f"springs per contact radius (default {ex.DEFAULT_RESOLUTION:g})",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_mindlin)


def _dimensionless(p):
    p.add_argument(
        "--delta",
        type=finite_float("delta", 0, 1),
        required=True,
        help="d2/d1 in [0, 1] (0: no contact in the back step)",
    )
    p.add_argument("--eps", type=finite_float("eps", -1e3, 1e3), required=True, help="v/(omega R)")
    p.add_argument(
        "--w",
        type=finite_float("w", 0, 1e4, lo_open=True),
        required=True,
        help="rolling amplitude W/a1 > 0 (Eq. 32 needs w >= 2)",
    )


def _working_point(args):
    ex.working_point(args.delta, args.eps, args.w, resolution=4)  # load the compiled kernel
    r = ex.working_point(args.delta, args.eps, args.w, resolution=args.resolution)
    if r["eq32"] is None:
        wpr = r.get("working_point_ratio")
        human = (
            f"v*/(omega R) simulated {r['simulated']:.6f}  (w < 2: Eq. 32 does not apply; "
            + (f"corrected formula {wpr:.6f})" if wpr is not None else "no steady state)")
            + f"  [{r['seconds']:.3f} s]"
        )
    else:
        rel = "n/a (Eq. 32 is 0)" if r["rel_error"] is None else f"{r['rel_error']:.2e}"
        human = (
            f"v*/(omega R) simulated {r['simulated']:.6f}  Eq. 32 {r['eq32']:.6f}  "
            f"Eq. 29 {r['eq29']:.6f}  rel. error {rel}  [{r['seconds']:.3f} s]"
        )
    if r.get("note"):
        human += f"\nnote: {r['note']}"
    emit(r, args.json, human)
    return 0


def _simulate(args):
    geo = ex.Geometry(a_over_r=args.a_over_r, g_over_e=args.g_over_e)
    # load the compiled kernel first, so `seconds` is the simulation alone
    ex.simulate(
        args.delta,
        args.eps,
        args.w,
        args.omega_n_ratio,
        mu=args.mu,
        periods=2,
        resolution=4,
        geo=geo,
        n_sub=1,
    )
    r = ex.simulate(
        args.delta,
        args.eps,
        args.w,
        args.omega_n_ratio,
        mu=args.mu,
        periods=args.periods,
        resolution=args.resolution,
        geo=geo,
        n_sub=args.n_sub,
    )
    eq = "n/a" if r["eq32"] is None else f"{r['eq32']:.6f}"
    human = (
        f"mean v*/(omega R) {r['mean_v_star_over_omega_R']:.6f} (Eq. 32: {eq})  slip work/"
        f"period {r['slip_work']:.3e} [2 G* a1^3]  energy residual {r['energy_residual']:.2e}"
        f"  [{r['seconds']:.3f} s, {r['n_sub']} sub-steps per half period]"
    )
    if r.get("step_note"):
        human += f"\nnote: {r['step_note']}"
    emit(r, args.json, human)
    return 0


def _mindlin(args):
    r = mindlin(args.mu, points=args.points, resolution=args.resolution)
    err = max(abs(a - b) for a, b in zip(r["T_over_muN"], r["analytic"]))
    human = "\n".join(
        ["u/u*     T/(mu N) sim   analytic"]
        + [
            f"{u:7.3f}  {t:12.6f}  {a:9.6f}"
            for u, t, a in zip(r["u_over_ustar"], r["T_over_muN"], r["analytic"])
        ]
        + [f"max |error| {err:.2e}"]
    )
    emit(r, args.json, human)
    return 0
