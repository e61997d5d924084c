"""Work-precision study: error against run time as the grid and the sub-step are refined.

Quantities (one line each on the plot, ``quantity`` column of the CSV):

* ``wp:<case>``       quasi-static working point (infinite friction and runner mass) vs Eq. 32,
  the exact reference, refining the grid (springs per contact radius a1).  The error is the
  worst over 8 alignments of the grid with the stroke (its sign changes with the alignment, its
  envelope falls at second order); the time is that of one working point (two runs of three
  periods, one sub-step per half period: the kernel is exact within a sub-step here).
* ``naive:<case>``    the same protocol (prescribed runner, square wave, impulse over the last
  period, affine in v*) with the plain-numpy spring row of ``tests/naive.py``, one alignment.
* ``dyn_v_grid`` / ``dyn_slip_grid``   mean runner velocity and slip work of a finite-mass,
  finite-friction run (``DYN``) vs a 4x finer grid, at a fixed fine sub-step;
* ``dyn_v_dt`` / ``dyn_slip_dt``       the same vs a 16x finer sub-step, at a fixed fine grid;
* ``mindlin``         max |T - T_Mindlin| / (mu N) of the Cattaneo-Mindlin curve (absolute in
  units of mu N, not relative), refining the grid.

Each row: quantity, refinement kind and value, error, seconds (best of ``repeats`` after a
warm-up call, which also loads or compiles the numba kernels).  The observed order is the
least-squares slope of -log(error) against log(refinement) over all points of a line.
"""
from __future__ import annotations

import csv
import importlib.util
import io
import time
from pathlib import Path

import numpy as np

from . import analytic
from . import experiments as ex
from .io import atomic_write, staged, write_text

WP_CASES = [(0.93, 0.2, 2.2), (0.7, 0.1, 2.5), (0.5, 0.3, 5.0)]
NAIVE_CASE = WP_CASES[1]
# finite mass (omega_n/Omega = 0.3) and friction (mu = 0.3) at eps = 0.995: partial slip, the
# slip work is ~97% of the drive work, the runner moves at about twice Eq. 32
DYN = dict(delta=0.7, eps=0.995, w=2.5, omega_n_ratio=0.3, mu=0.3, periods=20)
N_OFFSETS = 8


def _best_time(fn, repeats):
    val = fn()  # warm-up (numba compilation / cache load)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        val = fn()
        best = min(best, time.perf_counter() - t)
    return val, best


def naive_module():
    """tests/naive.py imported by path (the tests folder is not a package); None if absent."""
    path = Path(__file__).resolve().parent.parent / "tests" / "naive.py"
    if not path.exists():
        return None
    spec = importlib.util.spec_from_file_location("rolling_naive", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod




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
            err = max(abs(ex.working_point(*case, resolution=res, grid_offset=o)["simulated"]
                          - ref) for o in offsets) / abs(ref)
            rows.append(dict(quantity=f"wp:{case}", refine="resolution", value=res,
                             error=err, seconds=sec))
    return rows


def _naive_rows(res_list):
    naive = naive_module()
    if naive is None:
        return []
    ref = float(analytic.eq32(*NAIVE_CASE))
    rows = []
    for per_a in res_list:
        v, sec = _best_time(lambda: naive.working_point(*NAIVE_CASE, per_a), 1)
        rows.append(dict(quantity=f"naive:{NAIVE_CASE}", refine="resolution", value=per_a,
                         error=abs(v - ref) / abs(ref), seconds=sec))
    return rows


def _dyn_run(res, n_sub, periods):
    return ex.simulate(DYN["delta"], DYN["eps"], DYN["w"], DYN["omega_n_ratio"], mu=DYN["mu"],
                       periods=periods, resolution=res, n_sub=n_sub)


def _dyn_rows(kind, value, r, ref, sec):
    refine = "resolution" if kind == "grid" else "n_sub"
    out = []
    for key, q in (("mean_v_star_over_omega_R", "v"), ("slip_work", "slip")):
        err = abs(r[key] - ref[key]) / abs(ref[key])
        out.append(dict(quantity=f"dyn_{q}_{kind}", refine=refine, value=value, error=err,
                        seconds=sec))
    return out


def study(quick=False, repeats=3) -> list[dict]:
    """All rows of the study (``quick``: one working-point case, fewer and coarser points)."""
    rows = _wp_rows(WP_CASES[:1] if quick else WP_CASES,
                    [4, 8, 16, 32, 64, 128] if quick else [4, 8, 16, 32, 64, 128, 256, 512],
                    repeats)
    rows += _naive_rows([8, 16, 32] if quick else [8, 16, 32, 64, 128, 256])
    # dynamic: finite mass and friction against much finer references.  Sub-steps are counted
    # per half period; the cells per half period are 2.5 x resolution (w = 2.5).
    periods = 6 if quick else DYN["periods"]
    grid_nsub = 640 if quick else 2560           # fixed fine sub-step of the grid study
    grid_res = [8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]
    ref = _dyn_run(4 * grid_res[-1], grid_nsub, periods)
    for res in grid_res:
        r, sec = _best_time(lambda: _dyn_run(res, grid_nsub, periods), 1)
        rows += _dyn_rows("grid", res, r, ref, sec)
    dt_res = 16 if quick else 64                 # fixed fine grid of the sub-step study
    dt_nsub = [10, 20, 40, 80, 160] if quick else [10, 20, 40, 80, 160, 320, 640, 1280, 2560]
    ref = _dyn_run(dt_res, 16 * dt_nsub[-1], periods)
    for n_sub in dt_nsub:
        r, sec = _best_time(lambda: _dyn_run(dt_res, n_sub, periods), 1)
        rows += _dyn_rows("dt", n_sub, r, ref, sec)
    for res in ([8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]):
        r, sec = _best_time(lambda: ex.mindlin(0.3, points=41, resolution=res), repeats)
        err = float(np.max(np.abs(np.array(r["T_over_muN"]) - np.array(r["analytic"]))))
        rows.append(dict(quantity="mindlin", refine="resolution", value=res, error=err,
                         seconds=sec))
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
    ours = sorted(((r["error"], r["seconds"]) for r in rows
                   if r["quantity"] == f"wp:{NAIVE_CASE}"), reverse=True)
    out = []
    if not ours:
        return out
    le = np.log([e for e, _ in ours])[::-1]   # increasing error
    lt = np.log([t for _, t in ours])[::-1]
    for r in rows:
        if r["quantity"] != f"naive:{NAIVE_CASE}":
            continue
        t = float(np.exp(np.interp(np.log(r["error"]), le, lt)))
        out.append(dict(resolution=r["value"], error=r["error"], naive_seconds=r["seconds"],
                        ours_seconds=t, speedup=r["seconds"] / t))
    return out


def headline(rows) -> dict:
    """Errors of the working point at 16/32/64 springs per a1 and the time per working point."""
    out = {}
    for r in rows:
        if r["quantity"].startswith("wp:") and r["value"] in (16, 32, 64):
            out[f"{r['quantity']}@{r['value']:g}"] = dict(error=r["error"], seconds=r["seconds"])
    return out


@staged()  # both files new, or neither
def write(rows, out="results", name="work_precision") -> dict:
    """Write ``name``.csv (rows with the observed order per quantity) and ``name``.png."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    orders = summarize(rows)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["quantity", "refine", "value", "error", "seconds",
                                        "observed_order"], lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(dict(r, observed_order=round(orders[r["quantity"]], 3)))
    write_text(out / f"{name}.csv", buf.getvalue())
    fig, ax = plt.subplots(figsize=(11, 5.5))
    for q, p in orders.items():
        sel = [r for r in rows if r["quantity"] == q]
        style = "--" if q.startswith("naive") else "-"
        unit = {"resolution": "springs/a1", "n_sub": "sub-steps/half period"}[sel[0]["refine"]]
        ax.loglog([r["seconds"] for r in sel], [max(r["error"], 1e-16) for r in sel],
                  style, marker="o", ms=3,
                  label=f"{q}: {sel[0]['value']:g}..{sel[-1]['value']:g} {unit}, order {p:.2f}")
    ax.set_xlabel("wall time of one evaluation [s] (2-core machine, one thread, best of 3)")
    ax.set_ylabel("relative error (mindlin: max |T - T_Mindlin| / (mu N))")
    ax.set_title("Work-precision: refining the grid and the sub-step\n"
                 "wp: working point vs Eq. 32 (worst of 8 grid alignments); naive: plain "
                 "spring row; dyn: finite mass + friction", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    atomic_write(out / f"{name}.png", lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    return orders
