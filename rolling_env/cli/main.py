"""Command line: ``rolling-drive SUBCOMMAND ...`` (also ``python -m rolling_env``).

Each subcommand lives in ``rolling_env.cli.<module>`` and provides
``register(subparsers)``, which adds its parser and sets ``func`` (args -> exit code).
Bad arguments give a one-line error naming the parameter and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import re
import sys

from rolling_env.io import check_writable, interrupt_ends_process

COMMAND_MODULES = ["physics", "figures", "converge", "stability", "bench", "rollout", "accuracy"]


def checked_float(name, check):
    """argparse type: a float passed to ``check(name, x)``, a library check that returns it
    or raises ValueError naming ``name`` (the flag's name, so the message names the flag)."""

    def conv(text):
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        try:
            return check(name, x)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    conv.__name__ = name
    return conv


def finite_float(name, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False, allow_inf=False):
    """argparse type: a float checked by ``validation.check_range`` (message names the
    parameter)."""
    from rolling_env.validation import check_range

    return checked_float(
        name,
        lambda n, x: check_range(
            n, x, lo, hi, lo_open=lo_open, hi_open=hi_open, allow_inf=allow_inf
        ),
    )


def positive_int(name, lo=1, hi=10**9):
    def conv(text):
        try:
            x = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if not lo <= x <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be an integer in [{lo}, {hi}], got {x}")
        return x

    conv.__name__ = name
    return conv


def file_path(name):
    """argparse type: a path for one output file (not an existing folder, not ending in '/')."""

    def conv(text):
        import os

        if not text or text.endswith(("/", os.sep)) or os.path.isdir(text):
            raise argparse.ArgumentTypeError(
                f"{name} must be a file path (the report), got the folder {text!r}"
            )
        return text

    conv.__name__ = name
    return conv


def folder_path(name):
    """argparse type: a folder for output files (an existing file is refused)."""

    def conv(text):
        import os

        if not text or (os.path.exists(text) and not os.path.isdir(text)):
            raise argparse.ArgumentTypeError(f"{name} must be a folder, got the file {text!r}")
        return text

    conv.__name__ = name
    return conv


def add_report_arguments(p, default: str, quick_help: str) -> None:
    """``--out``, ``--quick`` and ``--json`` of a command that writes one report (read by
    ``report_out``)."""
    p.add_argument(
        "--out",
        type=file_path("out"),
        default=None,
        help=f"report path (default {default}, relative to the current "
        "directory; with --quick the report is only printed unless --out is "
        "given)",
    )
    p.add_argument("--quick", action="store_true", help=quick_help)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def report_out(args, default: str):
    """Where a command with ``--quick`` writes its report: ``--out`` where given, else
    ``default``, but nowhere for ``--quick`` without ``--out`` (a quick subset never replaces
    the full report); probed (``io.check_writable``) before the command computes anything."""
    out = args.out if (args.out is not None or args.quick) else default
    return None if out is None else check_writable(out)


def emit(result: dict, as_json: bool, human: str) -> None:
    """Print one JSON object on stdout (strict JSON: a non-finite number is written as the
    string "inf", "-inf" or "nan", which JSON has no number for), or a human summary."""
    if as_json:
        print(json.dumps(_jsonable(result), allow_nan=False))
    else:
        print(human)


def _jsonable(o):
    """``o`` with numpy values as Python ones, tuples as lists, non-finite floats as strings
    and anything else JSON has no type for as its ``str``."""
    import numpy as np

    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in (o.tolist() if isinstance(o, np.ndarray) else o)]
    if isinstance(o, (bool, np.bool_)):
        return bool(o)
    if isinstance(o, (int, np.integer)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        x = float(o)
        if math.isfinite(x):
            return x
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if o is None or isinstance(o, str):
        return o
    return str(o)


# A token argparse may take as a negative number rather than an option: its own pattern
# (-3, -0.5, -.5) misses an exponent and inf/nan, so "--target -3e-7" failed with "expected one
# argument".  No option of ours looks like a number, so every such token is a value.
_NEGATIVE_NUMBER = re.compile(
    r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE
)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # a private attribute of argparse (tests/cli/test_cli.py checks that negative values in
        # exponent form reach the commands, and that -inf gets the range message)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message):  # one line, exit code 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="rolling-drive", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"rolling_env.cli.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"rolling_env.cli.{name}":
                continue
            raise
        mod.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        # Ctrl-C ends the command, also inside a long compiled kernel call (the files it
        # writes are written whole or not at all, see rolling_env.io)
        with interrupt_ends_process():
            return int(args.func(args) or 0)
    except (ValueError, OSError) as e:  # validation errors from the library, or an output
        # path that cannot be written (--out names a file, no permission): one line, exit 2
        print(f"rolling-drive {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
