"""Subcommand figures: the paper's Figs. 6, 8, 9 -> results/paper/ (PNG + CSV)."""

from __future__ import annotations

from rolling_env.cli.main import emit, finite_float, folder_path, positive_int


def register(sub):
    p = sub.add_parser(
        "figures",
        help="regenerate the paper's Figs. 6, 8, 9 (PNG + CSV)",
        description="Simulate the force-sum and impulse maps (paper Figs. 6 and 8, "
        "delta 0.93, w 2.2) and the Eq. 32 working points (Fig. 9, delta 0.9, 0.7, "
        "0.5; w 2.2 and 10) and write PNG + CSV under --out; print the largest "
        "deviation of each simulated zero line from Eq. 29 / Eq. 32.",
    )
    p.add_argument(
        "--out",
        type=folder_path("out"),
        default="results/paper",
        help="output folder (default results/paper, relative to the current directory)",
    )
    p.add_argument(
        "--points",
        type=positive_int("points", 5, 401),
        default=41,
        help="grid points per axis of the maps (default 41)",
    )
    p.add_argument(
        "--resolution",
        type=finite_float("resolution", 2, 1e5),
        default=32.0,
        help="springs per contact radius a1 for the maps (default 32)",
    )
    p.add_argument(
        "--resolution9",
        type=finite_float("resolution9", 2, 1e5),
        default=64.0,
        help="springs per contact radius a1 for the Fig. 9 markers (default 64)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    from rolling_env.io import check_writable
    from rolling_env.studies.figures import make_figures

    check_writable(args.out, folder=True)
    r = make_figures(
        args.out, n=args.points, resolution=args.resolution, resolution9=args.resolution9
    )
    human = "\n".join(
        [
            f"wrote {r['out']}/fig6_force_sum, fig8_impulse, fig9_working_point (.png, .csv)",
            f"max |simulated zero - Eq. 29| (Fig. 6): {r['fig6_max_dev_from_eq29']:.2e}",
            f"max |simulated zero - Eq. 32| (Fig. 8): {r['fig8_max_dev_from_eq32']:.2e}",
            f"max |simulated working point - Eq. 32| (Fig. 9): {r['fig9_max_dev_from_eq32']:.2e}",
            "(in units of omega R)",
        ]
    )
    emit(r, args.json, human)
    return 0
