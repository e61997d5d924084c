"""Subcommand bench: speed and memory benchmarks -> results/benchmarks.md."""
from __future__ import annotations

from ..cli import emit, file_path


def register(sub):
    p = sub.add_parser("bench", help="speed and memory benchmarks (ratios in one run)",
                       description="Kernel throughput vs a machine-limit estimate, single env vs "
                       "Pendulum-v1, naive reference at equal accuracy, scene specialisation, "
                       "batched env, start-up and memory; writes a markdown report.")
    p.add_argument("--out", type=file_path("out"), default="results/benchmarks.md",
                   help="report path (default results/benchmarks.md, relative to the current "
                   "directory)")
    p.add_argument("--quick", action="store_true", help="fewer steps and scenes (report not written)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    from ..bench import report, run
    from ..io import write_text
    res = run(quick=args.quick)
    text = report(res)
    if not args.quick:
        write_text(args.out, text)
    emit(res, args.json, text)
    return 0
