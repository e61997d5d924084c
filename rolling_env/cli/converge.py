"""Subcommand converge: work-precision study -> results/work_precision.{csv,png}."""

from __future__ import annotations

from rolling_env.cli.main import emit, folder_path


def register(sub):
    p = sub.add_parser(
        "converge",
        help="error against run time as grid and sub-step shrink",
        description="Refine the grid (springs per contact radius) and the sub-step;"
        " record the error of the working point (vs Eq. 32), of a finite-mass, "
        "finite-friction run (vs a much finer reference), of the Cattaneo-Mindlin "
        "curve, and of the naive spring row, with the wall time of each; write "
        "work_precision.csv and .png (work_precision_quick.* with --quick) with "
        "the observed orders, and print the speed-up over the naive row at equal "
        "error.",
    )
    p.add_argument(
        "--out",
        type=folder_path("out"),
        default="results",
        help="output folder (default results, relative to the current directory)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="a smaller, faster subset (writes work_precision_quick.*)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    from rolling_env.io import check_writable
    from rolling_env.studies.converge import headline, speedup_at_equal_error, study, write

    check_writable(args.out, folder=True)
    name = "work_precision_quick" if args.quick else "work_precision"
    rows = study(quick=args.quick)
    orders = write(rows, args.out, name)
    speed = speedup_at_equal_error(rows)
    head = headline(rows)
    lines = [
        f"{r['quantity']:24s} {r['refine']:10s} {r['value']:>6g}  error {r['error']:.3e}"
        f"  {r['seconds'] * 1e3:9.3f} ms"
        for r in rows
    ]
    lines += ["", "observed orders:"] + [f"  {q:24s} {p:5.2f}" for q, p in orders.items()]
    lines += ["", "working point at 16 / 32 / 64 springs per a1 (error, time per working point):"]
    lines += [f"  {k:28s} {v['error']:.2e}  {v['seconds'] * 1e3:.3f} ms" for k, v in head.items()]
    if speed:
        lines += ["", "speed-up over the naive row at equal error:"]
        lines += [
            f"  naive {s['resolution']:>4g}/a1: error {s['error']:.2e}, naive "
            f"{s['naive_seconds'] * 1e3:8.2f} ms, ours {s['ours_seconds'] * 1e3:.3f} ms, "
            f"x{s['speedup']:.0f}"
            for s in speed
        ]
    lines += ["", f"wrote {args.out}/{name}.csv and .png"]
    emit(
        {"rows": rows, "orders": orders, "headline": head, "speedup": speed},
        args.json,
        "\n".join(lines),
    )
    return 0
