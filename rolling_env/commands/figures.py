"""Subcommand figures: the paper's Figs. 6, 8, 9 -> results/paper/ (PNG + CSV)."""
from __future__ import annotations

from ..cli import emit, finite_float, positive_int


def register(sub):
    p = sub.add_parser("figures", help="regenerate the paper's Figs. 6, 8, 9 (PNG + CSV)",
                       description="Simulate the force-sum and impulse maps (paper Figs. 6 and 8, "
                       "delta 0.93, w 2.2) and the Eq. 32 working points (Fig. 9) and write PNG + "
                       "CSV under --out.")
    p.add_argument("--out", default="results/paper", help="output folder (default results/paper)")
    p.add_argument("--points", type=positive_int("points", 5, 401), default=41,
                   help="grid points per axis of the maps (default 41)")
    p.add_argument("--resolution", type=finite_float("resolution", 2, 1e5), default=32.0,
                   help="springs per contact radius a1 (default 32)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    from ..figures import make_figures
    r = make_figures(args.out, n=args.points, resolution=args.resolution)
    emit(r, args.json, "\n".join(f"{k}: {v}" for k, v in r.items()))
    return 0
