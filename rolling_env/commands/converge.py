"""Subcommand converge: work-precision study -> results/work_precision.{csv,png}."""
from __future__ import annotations

from ..cli import emit


def register(sub):
    p = sub.add_parser("converge", help="error against run time as grid and sub-step shrink",
                       description="Refine the grid (springs per contact radius) and the sub-step;"
                       " record the error of the working point (vs Eq. 32), of a finite-mass, "
                       "finite-friction run (vs a much finer reference), of the Cattaneo-Mindlin "
                       "curve, and the naive spring row, with the wall time of each; write "
                       "work_precision.csv and .png with the observed orders.")
    p.add_argument("--out", default="results", help="output folder (default results)")
    p.add_argument("--quick", action="store_true", help="a smaller, faster subset")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    from ..converge import study, write
    name = "work_precision_quick" if args.quick else "work_precision"
    rows = study(quick=args.quick)
    orders = write(rows, args.out, name)
    lines = [f"{r['quantity']:28s} {r['refine']:10s} {r['value']:>7g}  error {r['error']:.3e}"
             f"  {r['seconds'] * 1e3:9.3f} ms" for r in rows]
    lines += ["observed orders: " + ", ".join(f"{q} {p:.2f}" for q, p in orders.items())]
    emit({"rows": rows, "orders": orders}, args.json, "\n".join(lines))
    return 0
