"""Work-precision study: error against run time as the grid and the sub-step are refined.

Quantities (one line each on the plot, ``quantity`` column of the CSV):

* ``wp:<case>``       quasi-static working point (infinite friction and runner mass) vs Eq. 32,
  the exact reference, refining the grid (springs per contact radius a1).  The error is the
  worst over 8 alignments of the grid with the stroke (its sign changes with the alignment, its
  envelope falls at second order); the time is that of one working point (two runs of three
  periods, one sub-step per half period: the kernel is exact within a sub-step here).
* ``naive:<case>``    the same protocol (prescribed runner, square wave, impulse over the last
  period, affine in v*) with the plain-numpy spring row of ``rolling_env.physics.naive``, one
  alignment.
* ``dyn_v_grid`` / ``dyn_slip_grid``   mean runner velocity and slip work of a finite-mass,
  finite-friction run (``DYN``) vs a 4x finer grid, at a fixed fine sub-step;
* ``dyn_v_dt`` / ``dyn_slip_dt``       the same vs a 16x finer sub-step, at a fixed fine grid;
* ``mindlin``         max |T - T_Mindlin| / (mu N) of the Cattaneo-Mindlin curve (absolute in
  units of mu N, not relative), refining the grid.
* ``env_x:<scene>`` / ``env_slip:<scene>``   the env's own episodes (``env_rows``): the
  standard episodes of ``rolling_env.studies.accuracy`` (Eq. 32 feedback, Eq. 32 open loop, uniform
  random actions; recorded at the scene's shipped settings) replayed open loop at the shipped
  grid with the shipped sub-steps per tick x ``ENV_SUB_FACTORS`` (refinement kind
  ``sub_steps``, value: sub-steps per tick), against the accuracy module's refined reference
  (its default levels ``accuracy.levels()``: sub-steps x 8 and x 16 with the grid x 4 and
  x 8, Richardson-extrapolated assuming second order).  ``env_x``:
  |x*(final) - reference| in the scene's tolerances; ``env_slip``: |slip work - reference| /
  reference (no line where the reference has no slip work: infinite friction).  The error is
  the worst of the episodes; the time is the env's step loop per step (``accuracy.replay``,
  fastest of ``repeats``, summed over the episodes and divided by their steps).
  ``env_x_grid:<scene>`` / ``env_slip_grid:<scene>`` refine the sub-steps and the grid
  together by ``ENV_BOTH_FACTORS`` (refinement kind ``sub_steps+grid``, value: the factor):
  at the shipped grid the x* error stops falling at the grid's own error.

Each row: quantity, refinement kind and value, error, seconds (best of ``repeats`` after a
warm-up call, which also loads or compiles the numba kernels).  The observed order is the
least-squares slope of -log(error) against log(refinement) over all points of a line.
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path

import numpy as np

from rolling_env.io import atomic_write, staged, write_text
from rolling_env.physics import analytic
from rolling_env.physics import experiments as ex
from rolling_env.physics.mindlin import mindlin

WP_CASES = [(0.93, 0.2, 2.2), (0.7, 0.1, 2.5), (0.5, 0.3, 5.0)]
NAIVE_CASE = WP_CASES[1]
# finite mass (omega_n/Omega = 0.3) and friction (mu = 0.3) at eps = 0.995: partial slip, the
# slip work is ~97% of the drive work, the runner moves at about twice Eq. 32
DYN = dict(delta=0.7, eps=0.995, w=2.5, omega_n_ratio=0.3, mu=0.3, periods=20)
N_OFFSETS = 8
# the env's episodes: sub-steps per tick x these at the shipped grid, and sub-steps and grid
# (cells per contact radius) x these together; the quick study takes ENV_QUICK_SCENES only
ENV_SUB_FACTORS = (0.25, 0.5, 1, 2, 4)
ENV_BOTH_FACTORS = (0.5, 1, 2, 4)
ENV_QUICK_SCENES = ("default",)


def _best_time(fn, repeats):
    val = fn()  # warm-up (numba compilation / cache load)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        val = fn()
        best = min(best, time.perf_counter() - t)
    return val, best


def order(x, err) -> float:
    """Observed convergence order: -slope of log(err) against log(x) (least squares)."""
    x, err = np.asarray(x, float), np.asarray(err, float)
    ok = err > 0
    if ok.sum() < 2:
        return float("nan")
    return float(-np.polyfit(np.log(x[ok]), np.log(err[ok]), 1)[0])


def _wp_rows(cases, res_list, repeats):
    rows = []
    offsets = np.arange(N_OFFSETS) / N_OFFSETS
    for case in cases:
        ref = float(analytic.eq32(*case))
        for res in res_list:
            _, sec = _best_time(lambda: ex.working_point(*case, resolution=res), repeats)
            err = max(
                abs(ex.working_point(*case, resolution=res, grid_offset=o)["simulated"] - ref)
                for o in offsets
            ) / abs(ref)
            rows.append(
                dict(quantity=f"wp:{case}", refine="resolution", value=res, error=err, seconds=sec)
            )
    return rows


def _naive_rows(res_list):
    from rolling_env.physics import naive

    ref = float(analytic.eq32(*NAIVE_CASE))
    rows = []
    for per_a in res_list:
        v, sec = _best_time(lambda: naive.working_point(*NAIVE_CASE, per_a), 1)
        rows.append(
            dict(
                quantity=f"naive:{NAIVE_CASE}",
                refine="resolution",
                value=per_a,
                error=abs(v - ref) / abs(ref),
                seconds=sec,
            )
        )
    return rows


def _dyn_run(res, n_sub, periods):
    return ex.simulate(
        DYN["delta"],
        DYN["eps"],
        DYN["w"],
        DYN["omega_n_ratio"],
        mu=DYN["mu"],
        periods=periods,
        resolution=res,
        n_sub=n_sub,
    )


def _dyn_rows(kind, value, r, ref, sec):
    refine = "resolution" if kind == "grid" else "n_sub"
    out = []
    for key, q in (("mean_v_star_over_omega_R", "v"), ("slip_work", "slip")):
        err = abs(r[key] - ref[key]) / abs(ref[key])
        out.append(
            dict(quantity=f"dyn_{q}_{kind}", refine=refine, value=value, error=err, seconds=sec)
        )
    return out


def env_episodes(scene, seed: int = 0, overrides=None) -> dict:
    """The standard episodes of ``rolling_env.studies.accuracy`` for ``scene``, recorded at its
    shipped settings (the Eq. 32 and random episodes of ``accuracy.scene_accuracy``'s plan, one
    random episode and no bang-bang one), each
    with its Richardson-extrapolated reference final x* and slip work at the accuracy module's
    default levels.  Returns the scene's ``name``, the shipped ``sub_steps`` and ``resolution``, the
    ``tolerance`` [m] and the ``episodes`` (label, actions, xstar_reference,
    slip_work_reference)."""
    import rolling_env
    from rolling_env.studies import accuracy as acc

    factors = acc.levels()
    ratio = factors[1][0] / factors[0][0]
    abs_levels = acc.check_levels(scene, factors, overrides)
    env = rolling_env.make(scene, **(overrides or {}))
    sc = env.unwrapped.scene
    s0, r0 = acc.shipped_numerics(env)
    steps, tol = sc.episode_steps, sc.tolerance
    env.close()
    rng = np.random.default_rng(seed)
    plan = [
        ("eq32-feedback", None),
        ("eq32-open-loop", None),
        ("random", rng.uniform(-1.0, 1.0, (steps, 3)).astype(np.float32)),
    ]
    episodes = []
    for kind, acts in plan:
        rec = acc.record(scene, kind, seed, acts, overrides)
        c, f = (acc.replay(scene, rec["actions"], seed, s, r, overrides) for s, r in abs_levels)
        episodes.append(
            dict(
                label=kind,
                actions=rec["actions"],
                xstar_reference=acc.richardson(c["xstar"], f["xstar"], ratio, acc.ORDER),
                slip_work_reference=acc.richardson(
                    c["slip_work"], f["slip_work"], ratio, acc.ORDER
                ),
            )
        )
    return dict(
        scene=scene,
        name=sc.name,
        sub_steps=s0,
        resolution=r0,
        tolerance=tol,
        seed=seed,
        episodes=episodes,
    )


def _env_level(ep, sub_steps, resolution, repeats, overrides=None) -> tuple[float, float, float]:
    """Worst x* error [tol] and relative slip-work error (nan without reference slip work) of
    the episodes of ``ep`` replayed at ``sub_steps`` and ``resolution``, and the seconds per
    env step (fastest of ``repeats`` step loops, summed over the episodes)."""
    from rolling_env.studies import accuracy as acc

    ex_, es, sec, steps = [], [], 0.0, 0
    for e in ep["episodes"]:
        r = acc.replay(
            ep["scene"], e["actions"], ep["seed"], sub_steps, resolution, overrides, repeats=repeats
        )
        ex_.append(abs(r["xstar"] - e["xstar_reference"]) / ep["tolerance"])
        ref = e["slip_work_reference"]
        es.append(abs(r["slip_work"] - ref) / abs(ref) if ref != 0.0 else np.nan)
        sec += r["seconds"]
        steps += len(e["actions"])
    slip = float("nan") if np.all(np.isnan(es)) else float(np.nanmax(es))
    return float(max(ex_)), slip, sec / steps


def env_rows(scene, repeats=3, both=True, seed=0, overrides=None) -> list[dict]:
    """Rows ``env_x:<scene>`` and ``env_slip:<scene>`` (sub-steps x ``ENV_SUB_FACTORS`` at the
    shipped grid) and, with ``both``, ``env_x_grid:<scene>`` and ``env_slip_grid:<scene>``
    (sub-steps and grid x ``ENV_BOTH_FACTORS``); see the module docstring."""
    ep = env_episodes(scene, seed, overrides)
    s0, r0 = ep["sub_steps"], ep["resolution"]
    name = ep["name"]
    rows = []

    def add(suffix, refine, value, shipped, x, slip, sec):
        rows.append(
            dict(
                quantity=f"env_x{suffix}:{name}",
                refine=refine,
                value=value,
                error=x,
                seconds=sec,
                shipped=shipped,
            )
        )
        if not np.isnan(slip):
            rows.append(
                dict(
                    quantity=f"env_slip{suffix}:{name}",
                    refine=refine,
                    value=value,
                    error=slip,
                    seconds=sec,
                    shipped=shipped,
                )
            )

    done = {}
    for f in ENV_SUB_FACTORS:
        n = max(1, round(s0 * f))
        if n not in done:
            done[n] = _env_level(ep, n, r0, repeats, overrides)
            add("", "sub_steps", n, n == s0, *done[n])
    if both:
        for f in ENV_BOTH_FACTORS:
            # factor 1 is the shipped env: the sub-step line's point (same run, same time)
            lev = (
                done[s0]
                if f == 1 and s0 in done
                else _env_level(ep, max(1, round(s0 * f)), r0 * f, repeats, overrides)
            )
            add("_grid", "sub_steps+grid", f, f == 1, *lev)
    return rows


def study(quick=False, repeats=3, env_scenes=None) -> list[dict]:
    """All rows of the study (``quick``: one working-point case, fewer and coarser points, the
    env's lines of ``ENV_QUICK_SCENES`` at the shipped grid only).  ``env_scenes``: the
    scenes of the env lines (default: every shipped scene, ``ENV_QUICK_SCENES`` with
    ``quick``; empty: none)."""
    rows = _wp_rows(
        WP_CASES[:1] if quick else WP_CASES,
        [4, 8, 16, 32, 64, 128] if quick else [4, 8, 16, 32, 64, 128, 256, 512],
        repeats,
    )
    rows += _naive_rows([8, 16, 32] if quick else [8, 16, 32, 64, 128, 256])
    # dynamic: finite mass and friction against much finer references.  Sub-steps are counted
    # per half period; the cells per half period are 2.5 x resolution (w = 2.5).
    periods = 6 if quick else DYN["periods"]
    grid_nsub = 640 if quick else 2560  # fixed fine sub-step of the grid study
    grid_res = [8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]
    ref = _dyn_run(4 * grid_res[-1], grid_nsub, periods)
    for res in grid_res:
        r, sec = _best_time(lambda: _dyn_run(res, grid_nsub, periods), 1)
        rows += _dyn_rows("grid", res, r, ref, sec)
    dt_res = 16 if quick else 64  # fixed fine grid of the sub-step study
    dt_nsub = [10, 20, 40, 80, 160] if quick else [10, 20, 40, 80, 160, 320, 640, 1280, 2560]
    ref = _dyn_run(dt_res, 16 * dt_nsub[-1], periods)
    for n_sub in dt_nsub:
        r, sec = _best_time(lambda: _dyn_run(dt_res, n_sub, periods), 1)
        rows += _dyn_rows("dt", n_sub, r, ref, sec)
    for res in [8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]:
        r, sec = _best_time(lambda: mindlin(0.3, points=41, resolution=res), repeats)
        err = float(np.max(np.abs(np.array(r["T_over_muN"]) - np.array(r["analytic"]))))
        rows.append(
            dict(quantity="mindlin", refine="resolution", value=res, error=err, seconds=sec)
        )
    if env_scenes is None:
        import rolling_env

        env_scenes = ENV_QUICK_SCENES if quick else rolling_env.list_scenes()
    for scene in env_scenes:
        rows += env_rows(scene, repeats=1 if quick else repeats, both=not quick)
    return rows


def summarize(rows) -> dict:
    """Observed order per quantity."""
    out = {}
    for q in dict.fromkeys(r["quantity"] for r in rows):
        sel = [r for r in rows if r["quantity"] == q]
        out[q] = order([r["value"] for r in sel], [r["error"] for r in sel])
    return out


def speedup_at_equal_error(rows) -> list[dict]:
    """For each naive point: the finite-volume kernel's time to reach the same error on the
    same case (log-log interpolation of its work-precision line; its coarsest point's time
    where the naive error is larger than all of ours), and the ratio of the two times."""
    ours = sorted(
        ((r["error"], r["seconds"]) for r in rows if r["quantity"] == f"wp:{NAIVE_CASE}"),
        reverse=True,
    )
    out = []
    if not ours:
        return out
    le = np.log([e for e, _ in ours])[::-1]  # increasing error
    lt = np.log([t for _, t in ours])[::-1]
    for r in rows:
        if r["quantity"] != f"naive:{NAIVE_CASE}":
            continue
        t = float(np.exp(np.interp(np.log(r["error"]), le, lt)))
        out.append(
            dict(
                resolution=r["value"],
                error=r["error"],
                naive_seconds=r["seconds"],
                ours_seconds=t,
                speedup=r["seconds"] / t,
            )
        )
    return out


def headline(rows) -> dict:
    """Errors of the working point at 16/32/64 springs per a1 and the time per working point."""
    out = {}
    for r in rows:
        if r["quantity"].startswith("wp:") and r["value"] in (16, 32, 64):
            out[f"{r['quantity']}@{r['value']:g}"] = dict(error=r["error"], seconds=r["seconds"])
    return out


def _env_panel(ax, rows, orders, prefix, ylabel, targets):
    """One panel of the env's lines: error against microseconds per env step, a colour per
    scene, solid at the shipped grid, dashed with the grid refined too; the shipped settings
    ringed; ``targets``: (value, label) horizontal guides."""
    from matplotlib import ticker

    qs = [q for q in orders if q.startswith((prefix + ":", prefix + "_grid:"))]
    # one colour per scene in both panels (the slip panel lacks the infinite-friction scenes)
    scenes = list(dict.fromkeys(q.split(":", 1)[1] for q in orders if q.startswith("env_")))
    colors = {sc: f"C{i % 10}" for i, sc in enumerate(scenes)}
    for y, lab in targets:
        ax.axhline(y, color="0.5", lw=0.8, ls=":")
        ax.annotate(
            lab,
            (1.0, y),
            xycoords=("axes fraction", "data"),
            ha="right",
            va="bottom",
            fontsize=7,
            color="0.35",
        )
    for q in qs:
        sel = [r for r in rows if r["quantity"] == q]
        sc = q.split(":", 1)[1]
        grid = q.startswith(prefix + "_grid:")
        x = [r["seconds"] * 1e6 for r in sel]
        y = [max(r["error"], 1e-16) for r in sel]
        if grid:
            lab = (
                f"{sc}, grid too: x{sel[0]['value']:g}..x{sel[-1]['value']:g}, "
                f"order {orders[q]:.2f}"
            )
        else:
            lab = (
                f"{sc}: {sel[0]['value']:g}..{sel[-1]['value']:g} sub-steps/tick, "
                f"order {orders[q]:.2f}"
            )
        ax.loglog(
            x,
            y,
            "--" if grid else "-",
            color=colors[sc],
            marker="s" if grid else "o",
            ms=3,
            lw=1.0 if grid else 1.4,
            label=lab,
        )
        for r, xi, yi in zip(sel, x, y):
            if r.get("shipped"):
                ax.plot(xi, yi, "o", ms=8, mfc="none", mec=colors[sc], mew=1.2)
    ax.set_xlabel("env step loop [microseconds per env step]")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(
        ticker.FuncFormatter(
            lambda v, _: f"{v:g}" if round(v / 10 ** np.floor(np.log10(v))) in (2, 5) else ""
        )
    )
    ax.legend(
        fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1, borderaxespad=0.0
    )


@staged()  # both files new, or neither
def write(rows, out="results", name="work_precision") -> dict:
    """Write ``name``.csv (rows with the observed order per quantity) and ``name``.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    orders = summarize(rows)
    buf = io.StringIO()
    w = csv.DictWriter(
        buf,
        fieldnames=["quantity", "refine", "value", "error", "seconds", "observed_order"],
        lineterminator="\n",
        extrasaction="ignore",
    )
    w.writeheader()
    for r in rows:
        w.writerow(dict(r, observed_order=round(orders[r["quantity"]], 3)))
    write_text(out / f"{name}.csv", buf.getvalue())
    env = any(q.startswith("env_") for q in orders)
    if env:
        fig = plt.figure(figsize=(12, 12.5))
        gs = fig.add_gridspec(2, 2, height_ratios=[1.0, 1.25], hspace=0.35, wspace=0.25)
        ax = fig.add_subplot(gs[0, :])
    else:
        fig, ax = plt.subplots(figsize=(11, 5.5))
    for q, p in orders.items():
        if q.startswith("env_"):
            continue
        sel = [r for r in rows if r["quantity"] == q]
        style = "--" if q.startswith("naive") else "-"
        unit = {"resolution": "springs/a1", "n_sub": "sub-steps/half period"}[sel[0]["refine"]]
        ax.loglog(
            [r["seconds"] for r in sel],
            [max(r["error"], 1e-16) for r in sel],
            style,
            marker="o",
            ms=3,
            label=f"{q}: {sel[0]['value']:g}..{sel[-1]['value']:g} {unit}, order {p:.2f}",
        )
    ax.set_xlabel("wall time of one evaluation [s] (2-core machine, one thread, best of 3)")
    ax.set_ylabel("relative error (mindlin: max |T - T_Mindlin| / (mu N))")
    ax.set_title(
        "Work-precision: refining the grid and the sub-step\n"
        "wp: working point vs Eq. 32 (worst of 8 grid alignments); naive: plain "
        "spring row; dyn: finite mass + friction",
        fontsize=9,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    if env:
        from rolling_env.studies.accuracy import TARGET_SLIP_PCT, TARGET_XSTAR_TOL

        ax1, ax2 = fig.add_subplot(gs[1, 0]), fig.add_subplot(gs[1, 1])
        _env_panel(
            ax1,
            rows,
            orders,
            "env_x",
            "final x* error [scene tolerances]",
            [(1.0, "1 tolerance"), (TARGET_XSTAR_TOL, f"{TARGET_XSTAR_TOL:g} tolerance")],
        )
        slip_target = TARGET_SLIP_PCT / 100.0
        _env_panel(
            ax2,
            rows,
            orders,
            "env_slip",
            "relative slip-work (wear) error",
            [(slip_target, f"{TARGET_SLIP_PCT:g}%")],
        )
        ax1.set_title(
            "env episodes vs the accuracy reference: final runner position x*\n"
            "worst of Eq. 32 feedback, open loop, random; ringed: shipped settings",
            fontsize=9,
        )
        ax2.set_title(
            "env episodes: slip work (none with infinite friction)\nsolid: "
            "sub-steps at the shipped grid; dashed: sub-steps and grid x factor",
            fontsize=9,
        )
    if not env:
        fig.tight_layout()
    atomic_write(
        out / f"{name}.png", lambda p: fig.savefig(p, dpi=110, format="png", bbox_inches="tight")
    )
    plt.close(fig)
    return orders
