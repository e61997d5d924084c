"""Subcommand stability: extreme and stiff cases -> results/stability.md."""
from __future__ import annotations

from ..cli import emit


def register(sub):
    p = sub.add_parser("stability", help="run the grid of stiff and extreme cases",
                       description="Runner mass from massless to infinite, mu from 1e-4 to inf, "
                       "delta near 0 and 1, w above/below 2, lift-off, maximal rates, a long run, "
                       "sub-steps from coarse to fine; check finiteness, energy, run time and "
                       "convergence; write a markdown report.")
    p.add_argument("--out", default="results/stability.md", help="report path")
    p.add_argument("--quick", action="store_true", help="a smaller, faster subset")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    from ..stability import report, run, write
    rows = run(quick=args.quick)
    text = write(rows, args.out) if not args.quick or args.out != "results/stability.md" \
        else report(rows)
    emit({"rows": rows}, args.json, text)
    return 0 if all(r["status"] == "PASS" for r in rows) else 1
