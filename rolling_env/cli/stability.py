"""Subcommand stability: extreme and stiff cases -> results/stability.md."""

from __future__ import annotations

from rolling_env.cli.main import add_report_arguments, emit, report_out

DEFAULT_OUT = "results/stability.md"


def register(sub):
    p = sub.add_parser(
        "stability",
        help="run the grid of stiff and extreme cases",
        description="Runner mass from omega_n/Omega = 1e-3 to massless, mu from "
        "1e-4 to inf, delta 1e-4 and 1, w above and below 2, lift-off mid-step, "
        "maximal rates (100 and 6400 cells per sub-step), a run of 1e5 ticks, "
        "sub-steps from 1 to 1e4 per half period, and at the env's own settings "
        "(default scene) runners from omega_n/Omega = 1e-3 to 1e4 and massless; "
        "check finiteness, the energy "
        "balance, run time and convergence; write a markdown table (PASS/FAIL per "
        "case, tolerances stated in it) and print it.  Exit code 1 if any case "
        "fails.",
    )
    add_report_arguments(p, DEFAULT_OUT, "a smaller, faster subset")
    p.set_defaults(func=_run)


def _run(args):
    from rolling_env.studies.stability import report, run, write

    out = report_out(args, DEFAULT_OUT)
    rows = run(quick=args.quick)
    text = report(rows) if out is None else write(rows, out)
    emit({"rows": rows}, args.json, text)
    return 0 if all(r["status"] == "PASS" for r in rows) else 1
