"""Subcommand bench: speed and memory benchmarks -> results/benchmarks.md."""

from __future__ import annotations

from rolling_env.cli.main import emit, file_path, report_out

DEFAULT_OUT = "results/benchmarks.md"


def register(sub):
    p = sub.add_parser(
        "bench",
        help="speed and memory benchmarks (ratios in one run)",
        description="Kernel throughput vs a machine-limit estimate, single env vs "
        "Pendulum-v1, naive reference at equal accuracy, scene specialisation, "
        "batched env, start-up and memory; writes a markdown report.",
    )
    p.add_argument(
        "--out",
        type=file_path("out"),
        default=None,
        help=f"report path (default {DEFAULT_OUT}, relative to the current "
        "directory; with --quick the report is only printed unless --out is "
        "given)",
    )
    p.add_argument("--quick", action="store_true", help="fewer steps and scenes")
    p.add_argument("--json", action="store_true", help="print one JSON object")
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
