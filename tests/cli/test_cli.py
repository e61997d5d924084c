"""The command line: JSON keys, numbers against the analytic results, clear errors with exit 2."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import pytest

from rolling_env.cli.main import main
from rolling_env.physics import analytic


def _strict(token):
    raise AssertionError(
        f"{token} is not JSON (a strict parser such as jq or JSON.parse rejects it)"
    )


def _json(capsys, *argv):
    """The command's stdout parsed as strict JSON (no NaN / Infinity tokens)."""
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out, parse_constant=_strict)


def test_json_writes_non_finite_numbers_as_strings(capsys):
    r = _json(
        capsys,
        "simulate",
        "--delta",
        "0.7",
        "--eps",
        "0.1",
        "--w",
        "2.5",
        "--omega-n-ratio",
        "inf",
        "--periods",
        "2",
        "--resolution",
        "16",
        "--json",
    )
    assert r["mu"] == "inf" and r["omega_n_ratio"] == "inf", (
        f"infinite friction / massless runner should read 'inf', got {r['mu']!r}, "
        f"{r['omega_n_ratio']!r}"
    )


def test_working_point_json(capsys):
    r = _json(capsys, "working-point", "--delta", "0.7", "--eps", "0.1", "--w", "2.5", "--json")
    assert {"simulated", "eq32", "eq29", "rel_error", "seconds"} <= set(r)
    assert abs(r["eq32"] - analytic.eq32(0.7, 0.1, 2.5)) < 1e-15
    assert r["rel_error"] < 1e-3, "default resolution should give about 0.1% or better"


def test_simulate_json(capsys):
    r = _json(
        capsys,
        "simulate",
        "--delta",
        "0.7",
        "--eps",
        "0.995",
        "--w",
        "2.5",
        "--omega-n-ratio",
        "0.3",
        "--mu",
        "0.3",
        "--periods",
        "6",
        "--resolution",
        "16",
        "--json",
    )
    assert {"mean_v_star_over_omega_R", "slip_work", "energy_residual", "seconds"} <= set(r)
    assert r["slip_work"] > 0 and abs(r["energy_residual"]) < 0.05


def test_mindlin_json(capsys):
    r = _json(capsys, "mindlin", "--mu", "0.3", "--points", "11", "--json")
    assert len(r["u_over_ustar"]) == len(r["T_over_muN"]) == len(r["analytic"]) == 11
    assert max(abs(a - b) for a, b in zip(r["T_over_muN"], r["analytic"])) < 2e-3


@pytest.mark.parametrize(
    "argv,name",
    [
        (["working-point", "--delta", "1.5", "--eps", "0.1", "--w", "2.5"], "delta"),
        (["working-point", "--delta", "0.7", "--eps", "nan", "--w", "2.5"], "eps"),
        (["working-point", "--delta", "0.7", "--eps", "0.1", "--w", "0"], "w"),
        (
            [
                "simulate",
                "--delta",
                "0.7",
                "--eps",
                "0.1",
                "--w",
                "2.5",
                "--omega-n-ratio",
                "1",
                "--mu",
                "-1",
            ],
            "mu",
        ),
        (["mindlin", "--mu", "0.3", "--points", "1"], "points"),
        (["mindlin", "--mu", "1e300"], "mu"),
        (
            [
                "simulate",
                "--delta",
                "0.7",
                "--eps",
                "0.1",
                "--w",
                "2.5",
                "--omega-n-ratio",
                "1",
                "--a-over-r",
                "1e-160",
            ],
            "a-over-r must be in [1e-06, 0.5]",
        ),
        (["rollout", "--target", "nan"], "target must be in (-inf, inf) (a finite number)"),
        # one message for every bad value: 0, inf or a finite value inside the range
        *[
            (
                ["simulate", "--delta", "0.7", "--eps", "0.1", "--w", "2.5", "--omega-n-ratio", r],
                "omega-n-ratio must be 0 (infinitely heavy runner), inf (massless) or in "
                "[1e-100, 1e+100], got",
            )
            for r in ("-1", "1e-170", "1e170", "nan", "-inf")
        ],
        (["rollout", "--controller", "zero", "--out", "{file}"], "out must be a folder"),
        (["figures", "--out", "{file}"], "out must be a folder"),
        (["stability", "--quick", "--out", "{dir}"], "out must be a file path"),
        (["bench", "--quick", "--out", "{dir}/"], "out must be a file path"),
    ],
)
def test_bad_arguments_exit_2_naming_the_parameter(argv, name, tmp_path, capsys):
    """Checked before any work: --out that names a folder where a report file is written
    (it wrote a file named like the folder) or a file where a folder is, --target NaN, ..."""
    f = tmp_path / "a_file"
    f.write_text("keep")
    argv = [a.replace("{file}", str(f)).replace("{dir}", str(tmp_path)) for a in argv]
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert name in err and len(err.strip().splitlines()) == 1, err


def test_console_script_help():
    out = subprocess.run(
        [sys.executable, "-m", "rolling_env", "simulate", "--help"], capture_output=True, text=True
    )
    assert out.returncode == 0 and "--omega-n-ratio" in out.stdout


@pytest.mark.parametrize("delta,eps", [(1.0, 0.1), (0.5, 1.0)])
def test_working_point_where_eq32_vanishes(delta, eps, capsys):
    """delta = 1 or eps = 1 are valid inputs where Eq. 32 is 0: no relative error, no crash."""
    r = _json(
        capsys, "working-point", "--delta", str(delta), "--eps", str(eps), "--w", "2.5", "--json"
    )
    assert r["rel_error"] is None and abs(r["eq32"]) < 1e-15
    assert abs(r["simulated"]) < 1e-9, f"no net drive expected, got {r['simulated']}"
    assert main(["working-point", "--delta", str(delta), "--eps", str(eps), "--w", "2.5"]) == 0
    assert "n/a" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv,name",
    [
        (["rollout", "--controller", "zero", "--out", "{file}/sub"], "a_file"),
        (["rollout", "--scene", "defualt"], "--scene: unknown scene 'defualt'"),
    ],
)
def test_library_errors_exit_2_in_one_line(argv, name, tmp_path, capsys):
    """Range errors raised by the library and unwritable outputs: one line naming the cause."""
    f = tmp_path / "a_file"
    f.write_text("keep")
    argv = [a.replace("{file}", str(f)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert name in err and len(err.strip().splitlines()) == 1, err
    assert f.read_text() == "keep"


@pytest.mark.parametrize("eps", [0.1, -0.4])
def test_delta_zero_accepted_and_gives_one_minus_eps(eps, capsys):
    """--delta 0 (no back-step contact) is a valid input (it was refused as outside (0, 1]):
    working-point gives v*/(omega R) = 1 - eps (Eq. 32 at delta = 0) to 1e-9, and simulate
    runs (heavy runner: the zero-impulse velocity, the same 1 - eps to 1e-9)."""
    r = _json(capsys, "working-point", "--delta", "0", "--eps", str(eps), "--w", "2.5", "--json")
    assert abs(r["simulated"] - (1 - eps)) < 1e-9 and abs(r["eq32"] - (1 - eps)) < 1e-15, r
    r = _json(
        capsys,
        "simulate",
        "--delta",
        "0",
        "--eps",
        str(eps),
        "--w",
        "2.5",
        "--omega-n-ratio",
        "0",
        "--periods",
        "4",
        "--json",
    )
    assert abs(r["mean_v_star_over_omega_R"] - (1 - eps)) < 1e-9, r


def test_rollout_files_are_named_by_the_scene_key_not_the_yaml_name(tmp_path, capsys):
    """A copy of a shipped scene with other values keeps the shipped ``name:`` inside; its
    rollout must not land on (and overwrite) the shipped scene's files."""
    import yaml

    from rolling_env.env.scenes import SCENE_DIR

    shipped = yaml.safe_load((SCENE_DIR / "default.yaml").read_text())
    custom = dict(shipped, mu=0.01)  # name stays "default"
    (tmp_path / "sc").mkdir()
    same_stem = tmp_path / "sc" / "default.yaml"
    other_stem = tmp_path / "sc" / "slippery.yaml"
    for p in (same_stem, other_stem):
        p.write_text(yaml.safe_dump(custom))
    out = tmp_path / "out"
    names = []
    for scene in ("default", str(same_stem), str(other_stem)):
        r = _json(
            capsys, "rollout", "--scene", scene, "--controller", "zero", "--out", str(out), "--json"
        )
        names.append(json.loads(json.dumps(r))["csv"])
    assert len(set(names)) == 3, f"rollouts share files: {names}"
    assert names[0].endswith("default_zero_seed0.csv"), names[0]
    assert "default-" in names[1] and names[2].endswith("slippery_zero_seed0.csv"), names
    assert len(list(out.glob("*.csv"))) == 3, sorted(p.name for p in out.iterdir())


def test_negative_values_in_exponent_form_are_values(capsys):
    """argparse takes "-3e-7" for an option unless told otherwise ("expected one argument")."""
    r = _json(
        capsys,
        "working-point",
        "--delta",
        "0.7",
        "--eps",
        "-5e-1",
        "--w",
        "2.5",
        "--resolution",
        "16",
        "--json",
    )
    assert r["eq32"] == pytest.approx(analytic.eq32(0.7, -0.5, 2.5), rel=1e-15), r
    with pytest.raises(SystemExit) as e:  # argparse's own exit, code 2
        main(["working-point", "--delta", "0.7", "--eps", "-inf", "--w", "2.5"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "eps must be" in err and "expected one argument" not in err, err


def test_negative_target_in_exponent_form_reaches_the_rollout(tmp_path, capsys):
    r = _json(
        capsys,
        "rollout",
        "--controller",
        "zero",
        "--target",
        "-3e-7",
        "--out",
        str(tmp_path),
        "--json",
    )
    assert r["target"] == -3e-7, r


def test_staged_writes_are_all_or_none(tmp_path):
    """Inside ``staged()`` the files appear only at the end of the block, all together; an
    error anywhere leaves every old file as it was and no temporary file behind; a nested
    block joins the outer one."""
    from rolling_env.io import staged, write_text

    a, b = tmp_path / "a.csv", tmp_path / "b.png"
    write_text(a, "old a")
    with pytest.raises(RuntimeError):
        with staged():
            write_text(a, "new a")
            assert a.read_text() == "old a", "renamed before the block ended"
            write_text(b, "new b")
            raise RuntimeError("fails after two writes")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"] and a.read_text() == "old a"
    with staged():
        write_text(a, "new a")
        with staged():
            write_text(b, "new b")
        assert not b.exists(), "the nested block renamed its file before the outer one ended"
    assert a.read_text() == "new a" and b.read_text() == "new b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.png"]


def _sigint_as_in_a_terminal():
    """preexec_fn: Ctrl-C reaches the child as it does from an interactive shell (a
    background job of a non-interactive shell, a CI runner's, ignores SIGINT, and children
    inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_ends_a_long_compiled_run():
    """One simulate of 1e9 sub-steps per tick is a single numba call, which never returns to
    the interpreter to raise KeyboardInterrupt: Ctrl-C (SIGINT) left it running for minutes.
    The CLI gives SIGINT the OS default while the command runs, so the process ends on it
    (killed by SIGINT, not a KeyboardInterrupt traceback after the call)."""
    import signal
    import time

    def simulate(n_sub):
        args = "simulate --delta 0.7 --eps 0.1 --w 2.5 --omega-n-ratio 5 --periods 2 --n-sub"
        return args.split() + [str(n_sub)]

    # the kernel compiled (or loaded from the cache) first, so that the signal below meets
    # the long call, not the compiler
    assert main(simulate(1)) == 0
    proc = subprocess.Popen(
        [sys.executable, "-m", "rolling_env", *simulate(1_000_000_000)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_sigint_as_in_a_terminal,
    )
    try:
        time.sleep(6)  # imports done: the command (its compile or its kernel call) is running
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = proc.stderr.read().decode()
    # killed by the signal: no KeyboardInterrupt traceback (what Python's own handler gives
    # when the interrupt arrives between bytecodes, e.g. while still importing)
    assert rc == -signal.SIGINT and "KeyboardInterrupt" not in err, f"exit {rc}: {err[-500:]}"


def test_ctrl_c_while_writing_still_removes_the_temporary_files(tmp_path):
    """Where the CLI made SIGINT end the process, a file write switches KeyboardInterrupt
    back on (io.interrupt_raises): Ctrl-C during a staged write removes its temporary files and
    leaves the old file, and the CLI's setting is restored after the block.  Run in a child
    process (the signal is sent to itself)."""
    script = f"""
import os, signal
from pathlib import Path
from rolling_env.io import interrupt_ends_process, staged, write_text
out = Path({str(tmp_path)!r})
write_text(out / "a.csv", "old a")
with interrupt_ends_process():
    assert signal.getsignal(signal.SIGINT) is signal.SIG_DFL
    try:
        with staged():
            write_text(out / "a.csv", "new a")
            os.kill(os.getpid(), signal.SIGINT)
            raise SystemExit("no KeyboardInterrupt")
    except KeyboardInterrupt:
        print("interrupted")
    assert signal.getsignal(signal.SIGINT) is signal.SIG_DFL, "not restored after the block"
print(sorted(p.name for p in out.iterdir()), (out / "a.csv").read_text())
"""
    r = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=_sigint_as_in_a_terminal,
    )
    assert r.returncode == 0, r.stderr[-1000:]
    assert r.stdout.split() == ["interrupted", "['a.csv']", "old", "a"], r.stdout


def test_sigterm_while_writing_removes_the_temporary_files(tmp_path):
    """SIGTERM (what ``timeout`` and job schedulers send) during a staged write removed
    nothing: the process ended at once and left hidden temporary files beside the outputs
    for good.  Now it removes them, leaves the old file and still exits 143 (128 + SIGTERM);
    outside a write SIGTERM keeps the OS default.  Run in a child process."""
    script = f"""
import os, signal
from pathlib import Path
from rolling_env.io import interrupt_ends_process, staged, write_text
out = Path({str(tmp_path)!r})
write_text(out / "a.csv", "old a")
with interrupt_ends_process():
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    with staged():
        write_text(out / "a.csv", "new a")
        write_text(out / "b.png", "new b")
        os.kill(os.getpid(), signal.SIGTERM)
        print("not terminated")
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert r.returncode == 128 + signal.SIGTERM, f"exit {r.returncode}: {r.stderr[-1000:]}"
    assert "not terminated" not in r.stdout and "Traceback" not in r.stderr, r
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"], sorted(
        p.name for p in tmp_path.iterdir()
    )
    assert (tmp_path / "a.csv").read_text() == "old a"


@pytest.mark.parametrize(
    "argv,compute",
    [
        (["figures"], "rolling_env.studies.figures.make_figures"),
        (["converge", "--quick"], "rolling_env.studies.converge.study"),
        (["stability", "--quick"], "rolling_env.studies.stability.run"),
        (["stability"], "rolling_env.studies.stability.run"),
        (["bench", "--quick"], "rolling_env.studies.bench.run"),
        (["rollout", "--controller", "zero"], "rolling_env.env.rollout.rollout"),
    ],
)
def test_unwritable_out_fails_before_any_work(tmp_path, capsys, monkeypatch, argv, compute):
    """An --out that cannot take files (here: below a file) is refused in one line naming
    --out, exit 2, before the command computes anything (it was found only when the results
    were written, after all the work, with an OS message that named neither --out nor the
    cause: "[Errno 17] File exists: '/etc/passwd'")."""
    import importlib

    blocker = tmp_path / "file"
    blocker.write_text("x")
    mod, fn = compute.rsplit(".", 1)
    monkeypatch.setattr(
        importlib.import_module(mod),
        fn,
        lambda *a, **k: pytest.fail("computed before checking --out"),
    )
    out = blocker / ("report.md" if argv[0] in ("stability", "bench") else "sub")
    assert main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out: cannot write {str(out)!r}: {str(blocker)!r} is a file" in err, err
    # the probe creates no folder (a missing one is made by the writes, after the work)
    from rolling_env.io import check_writable

    fresh = tmp_path / "new" / "deeper"
    assert check_writable(fresh / "x.md") == fresh / "x.md"
    assert check_writable(fresh, folder=True) == fresh
    assert not (tmp_path / "new").exists(), "the probe made a folder"


@pytest.mark.parametrize(
    "command,module,report_module,default",
    [
        (
            "stability",
            "rolling_env.studies.stability",
            "rolling_env.studies.stability",
            "results/stability.md",
        ),
        (
            "bench",
            "rolling_env.studies.bench",
            "rolling_env.studies.bench_report",
            "results/benchmarks.md",
        ),
    ],
)
def test_quick_report_is_written_only_where_out_is_given(
    tmp_path, monkeypatch, capsys, command, module, report_module, default
):
    """--quick never writes the full report's default path, also when it is spelled
    differently (./results/... was compared as a string and overwrote the full report with
    the quick subset), and writes the report where --out is given (bench --quick ignored
    --out without a word).  The computation is replaced by a stub: this checks where the CLI
    writes, not what it computes."""
    import importlib

    mod = importlib.import_module(module)
    monkeypatch.setattr(mod, "run", lambda quick=False: [] if command == "stability" else {})
    monkeypatch.setattr(
        importlib.import_module(report_module), "report", lambda rows: "QUICK REPORT\n"
    )
    monkeypatch.chdir(tmp_path)
    assert main([command, "--quick"]) == 0
    assert not (tmp_path / default).exists(), "--quick wrote the full report's path"
    given = "./" + default
    assert main([command, "--quick", "--out", given]) == 0
    assert (tmp_path / default).read_text() == "QUICK REPORT\n", "--out given but not written"
    capsys.readouterr()


def test_rollout_writes_its_csv_and_plot_together(tmp_path, capsys):
    """A plot that cannot be written (its name taken by a folder) left the new CSV beside it,
    over an earlier rollout a new CSV beside an old plot: now neither changes (exit 2)."""
    out = tmp_path / "out"
    (out / "default_zero_seed0.png").mkdir(parents=True)
    assert main(["rollout", "--controller", "zero", "--out", str(out)]) == 2
    assert "default_zero_seed0.png" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["default_zero_seed0.png"], sorted(
        p.name for p in out.iterdir()
    )


def test_figures_are_written_all_or_none(tmp_path, monkeypatch):
    """make_figures writes Figs. 6, 8 and 9: a failure while writing Fig. 9 left new Figs. 6
    and 8 beside an old Fig. 9; now no file of the set is written."""
    import matplotlib.figure

    from rolling_env.studies import figures

    calls = []
    real = matplotlib.figure.Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        calls.append(fname)
        if len(calls) == 3:  # fig6, fig8, then fig9's PNG
            raise OSError(28, "No space left on device")
        return real(self, fname, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    monkeypatch.setattr(figures, "FIG9_DELTAS", (0.7,))
    with pytest.raises(OSError, match="No space left"):
        figures.make_figures(tmp_path, n=5, resolution=4, resolution9=4)
    assert len(calls) == 3, calls
    assert list(tmp_path.iterdir()) == [], sorted(p.name for p in tmp_path.iterdir())
