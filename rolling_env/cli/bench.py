"""Subcommand bench: speed and memory benchmarks -> results/benchmarks.md."""

from __future__ import annotations

from rolling_env.cli.main import add_report_arguments, emit, report_out

DEFAULT_OUT = "results/benchmarks.md"


def register(sub):
    p = sub.add_parser(
        "bench",
        help="speed and memory benchmarks (ratios in one run)",
        description="Kernel throughput vs a machine-limit estimate, single env vs "
        "Pendulum-v1, naive reference at equal accuracy, scene specialisation, "
        "batched env, start-up and memory; writes a markdown report.",
    )
    add_report_arguments(p, DEFAULT_OUT, "fewer steps and scenes")
    p.set_defaults(func=_run)


def _run(args):
    from rolling_env.io import write_text
    from rolling_env.studies.bench import run
    from rolling_env.studies.bench_report import report

    out = report_out(args, DEFAULT_OUT)
    res = run(quick=args.quick)
    text = report(res)
    if out is not None:
        write_text(out, text)
    emit(res, args.json, text)
    return 0
