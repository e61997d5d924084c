"""Work-precision study: error against run time as the grid and the sub-step are refined.

Quantities (one line each on the plot):
* ``wp:<case>``      quasi-static working point vs Eq. 32 (exact reference), grid refinement;
  the error is the worst over 8 alignments of the grid with the stroke (it changes sign with
  the alignment; its envelope falls at second order);
* ``naive:<case>``   the same with the plain-numpy spring row of tests/naive.py;
* ``dyn_v_grid`` / ``dyn_slip_grid``   mean runner velocity and slip work of a finite-mass,
  finite-friction run vs a much finer grid (sub-step fixed and fine);
* ``dyn_v_dt`` / ``dyn_slip_dt``       the same vs a much finer sub-step (grid fixed);
* ``mindlin``        max error of the Cattaneo-Mindlin curve vs its analytic law.
Each row: quantity, refinement value, error, seconds (best of ``repeats`` after a warm-up).
The observed order is the least-squares slope of log(error) against log(refinement).
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
from .excitation import SquareWave
from .io import atomic_write, write_text

WP_CASES = [(0.93, 0.2, 2.2), (0.7, 0.1, 2.5), (0.5, 0.3, 5.0)]
DYN = dict(delta=0.7, eps=0.995, w=2.5, omega_n_ratio=0.3, mu=0.3, periods=20)


def _best_time(fn, repeats):
    fn()  # warm-up (compilation / cache load)
    best, val = np.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        val = fn()
        best = min(best, time.perf_counter() - t)
    return val, best


def _naive_module():
    path = Path(__file__).resolve().parent.parent / "tests" / "naive.py"
    if not path.exists():
        return None
    spec = importlib.util.spec_from_file_location("rolling_naive", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def order(x, err) -> float:
    """Observed convergence order: -slope of log(err) against log(x)."""
    x, err = np.asarray(x, float), np.asarray(err, float)
    ok = err > 0
    if ok.sum() < 2:
        return float("nan")
    return float(-np.polyfit(np.log(x[ok]), np.log(err[ok]), 1)[0])


def study(quick=False, repeats=3) -> list[dict]:
    rows = []
    res_list = [4, 8, 16, 32, 64, 128] if quick else [4, 8, 16, 32, 64, 128, 256, 512]
    cases = WP_CASES[:1] if quick else WP_CASES
    offsets = np.arange(8) / 8.0
    for case in cases:
        ref = float(analytic.eq32(*case))
        for res in res_list:
            # worst case over 8 grid alignments: the error's envelope, not a lucky alignment
            _, sec = _best_time(lambda: ex.working_point(*case, resolution=res), repeats)
            err = max(abs(ex.working_point(*case, resolution=res, grid_offset=o)["simulated"]
                          - ref) for o in offsets) / abs(ref)
            rows.append(dict(quantity=f"wp:{case}", refine="resolution", value=res,
                             error=err, seconds=sec))
    naive = _naive_module()
    if naive is not None:
        case = WP_CASES[1]
        ref = float(analytic.eq32(*case))
        for per_a in ([8, 16, 32] if quick else [8, 16, 32, 64, 128, 256]):
            v, sec = _best_time(lambda: naive.working_point(*case, per_a), 1)
            rows.append(dict(quantity=f"naive:{case}", refine="resolution", value=per_a,
                             error=abs(v - ref) / abs(ref), seconds=sec))
    # dynamic: finite mass and friction against much finer references
    periods = 6 if quick else DYN["periods"]
    dyn = dict(DYN, periods=periods)
    base_nsub = ex.default_substeps(dyn["omega_n_ratio"], SquareWave(
        dyn["delta"], dyn["eps"], dyn["w"], ex.Geometry().a1, ex.Geometry().R), 16)

    def run(res, n_sub):
        return ex.simulate(dyn["delta"], dyn["eps"], dyn["w"], dyn["omega_n_ratio"],
                           mu=dyn["mu"], periods=periods, resolution=res, n_sub=n_sub)
    fine_nsub = 4 * base_nsub
    ref = run(256 if quick else 512, fine_nsub)
    for res in ([8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]):
        r, sec = _best_time(lambda: run(res, fine_nsub), 1)
        rows += _dyn_rows("grid", res, r, ref, sec)
    ref = run(32, 64 * base_nsub)
    for mult in ([0.25, 0.5, 1, 2] if quick else [0.25, 0.5, 1, 2, 4, 8]):
        n_sub = max(1, int(round(mult * base_nsub)))
        r, sec = _best_time(lambda: run(32, n_sub), 1)
        rows += _dyn_rows("dt", n_sub, r, ref, sec)
    for res in ([8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]):
        r, sec = _best_time(lambda: ex.mindlin(0.3, points=41, resolution=res), repeats)
        err = float(np.max(np.abs(np.array(r["T_over_muN"]) - np.array(r["analytic"]))))
        rows.append(dict(quantity="mindlin", refine="resolution", value=res, error=err,
                         seconds=sec))
    return rows


def _dyn_rows(kind, value, r, ref, sec):
    ev = abs(r["mean_v_star_over_omega_R"] - ref["mean_v_star_over_omega_R"]) / abs(
        ref["mean_v_star_over_omega_R"])
    es = abs(r["slip_work"] - ref["slip_work"]) / abs(ref["slip_work"])
    refine = "resolution" if kind == "grid" else "n_sub"
    return [dict(quantity=f"dyn_v_{kind}", refine=refine, value=value, error=ev, seconds=sec),
            dict(quantity=f"dyn_slip_{kind}", refine=refine, value=value, error=es, seconds=sec)]


def summarize(rows) -> dict:
    out = {}
    for q in dict.fromkeys(r["quantity"] for r in rows):
        sel = [r for r in rows if r["quantity"] == q]
        out[q] = order([r["value"] for r in sel], [r["error"] for r in sel])
    return out


def write(rows, out="results", name="work_precision") -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    orders = summarize(rows)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["quantity", "refine", "value", "error", "seconds",
                                        "observed_order"])
    w.writeheader()
    for r in rows:
        w.writerow(dict(r, observed_order=round(orders[r["quantity"]], 3)))
    write_text(out / f"{name}.csv", buf.getvalue())
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for q, p in orders.items():
        sel = [r for r in rows if r["quantity"] == q]
        style = "--" if q.startswith("naive") else "-"
        ax.loglog([r["seconds"] for r in sel], [max(r["error"], 1e-16) for r in sel],
                  style, marker="o", ms=3, label=f"{q} (order {p:.2f})")
    ax.set_xlabel("wall time of one evaluation [s] (2-core machine, single thread)")
    ax.set_ylabel("relative error")
    ax.set_title("Work-precision: refining the grid (springs per a1) and the sub-step")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out / f"{name}.png", lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    return orders
