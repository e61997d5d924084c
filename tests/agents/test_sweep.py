"""agents.sweep: grids and searches on Ray Tune, run for real on short budgets.

The sweep file checks run without Ray; the sweeps themselves are skipped where Ray (the
``sweep`` extra) is not installed.  Ray's temporary files go under pytest's own.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest
import yaml

from agents import sweep as S

REPO = Path(__file__).resolve().parents[2]
TINY = {"n_timesteps": 4096, "eval_freq": 4096, "eval_episodes": 1}  # seconds per trial


def _write(path: Path, cfg: dict) -> Path:
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def _grid(tmp_path, **kw) -> dict:
    return {
        "kind": "grid",
        "name": "g",
        "scenes": ["default"],
        "algos": ["ppo"],
        "seeds": [0, 1],
        "runs": str(tmp_path / "runs"),
        "storage": str(tmp_path / "state"),
        **TINY,
        **kw,
    }


@pytest.fixture(scope="module")
def ray_tmp(tmp_path_factory):
    """Ray's temporary files: a short path (its socket paths must stay under 108 bytes)."""
    return tmp_path_factory.mktemp("ray")


def _sweep(tmp_path, config: Path, *extra, ray_tmp=None, timeout=240):
    """Run ``python -m agents.sweep`` as a user would (Ray's temporary files in ray_tmp)."""
    env = dict(os.environ, **({"RAY_TMPDIR": str(ray_tmp)} if ray_tmp else {}))
    if "--address" in extra:
        env = _joined(env)
    return subprocess.run(
        [sys.executable, "-m", "agents.sweep", "--config", str(config), *extra],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.fixture(scope="module")
def ray_head(ray_tmp):
    """A Ray cluster of this machine alone, started as the docs say (`ray start --head`,
    here with --block so that SIGTERM ends it), joined with --address; its address."""
    pytest.importorskip("ray.tune")
    with socket.socket() as sock:  # a free port: another Ray may hold the default one
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    head = subprocess.Popen(
        [
            str(Path(sys.executable).parent / "ray"),
            "start",
            "--head",
            "--block",
            "--port",
            str(port),
            "--num-cpus",
            "2",
            "--include-dashboard",
            "false",
            "--temp-dir",
            str(ray_tmp),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=_joined(),
    )
    address = None
    for line in head.stdout:
        m = re.search(r"--address='([^']+)'", line)
        address = address or (m and m.group(1))
        if "will now block" in line:
            break
    assert address and head.poll() is None, "ray start --head failed"
    threading.Thread(target=head.stdout.read, daemon=True).start()  # keep its pipe drained
    yield address
    head.terminate()
    try:
        head.wait(timeout=60)
    except subprocess.TimeoutExpired:
        head.kill()


# the test cluster's token, given to the head and to every driver that joins it (so that
# the tests neither need nor write ~/.ray/auth_token)
_TOKEN = uuid.uuid4().hex


def _joined(env=None) -> dict:
    """The environment of the test cluster's head and of a sweep that joins it: Ray 2.59 and
    later protect a cluster with a token, which `ray start --head` takes (since 2.60) only
    where one exists and a driver naming an address uses only with RAY_AUTH_MODE=token.
    Ray before 2.59 ignores both variables."""
    return dict(env or os.environ, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=_TOKEN)


# ------------------------------------------------------------------ bad sweep files
BAD = {
    "unknown key": ({"sedes": [0]}, "'sedes'"),
    "unknown scene": ({"scenes": ["no_such_scene"]}, "'scenes'"),
    "unknown algorithm": ({"algos": ["a2c"]}, "'algos'"),
    "empty seeds": ({"seeds": []}, "'seeds'"),
    "no agents": ({"algos": []}, "'algos' and 'configs'"),
    "seed of the wrong type": ({"seeds": ["zero"]}, "'seeds'"),
    "budget of the wrong type": ({"n_timesteps": "many"}, "'n_timesteps'"),
    "negative failures": ({"max_failures": -1}, "'max_failures'"),
    "configuration without algo": ({"configs": {"wide": {"conf": "x.yml"}}}, "'configs.wide'"),
    "configuration key": (
        {"configs": {"wide": {"algo": "ppo", "cnf": "x.yml"}}},
        "'configs.wide.cnf'",
    ),
    "bad hyper-parameter file": (
        {"configs": {"wide": {"algo": "ppo", "conf": "none.yml"}}},
        "'configs.wide'",
    ),
    "kind": ({"kind": "grids"}, "'kind'"),
}
SEARCH = {
    "kind": "search",
    "name": "s",
    "scene": "default",
    "algo": "ppo",
    "trials": 3,
    "space": {"learning_rate": {"loguniform": [1.0e-4, 1.0e-3]}},
    "output": "best.yml",
    **TINY,
}
BAD_SEARCH = {
    "unknown hyper-parameter": (
        {"space": {"learning_rat": {"uniform": [0.1, 0.2]}}},
        "'space.learning_rat'",
    ),
    "range outside the checks": ({"space": {"gamma": {"uniform": [0.9, 1.5]}}}, "'space.gamma'"),
    "unknown distribution": ({"space": {"gamma": {"normal": [0.9, 0.99]}}}, "'space.gamma'"),
    "searched budget": ({"space": {"n_timesteps": {"int": [1000, 2000]}}}, "'space.n_timesteps'"),
    "grid key in a search": ({"seeds": [0, 1]}, "'seeds'"),
    "no output": ({"output": None}, "'output'"),
    "no evaluation within the budget": ({"eval_freq": 10**6}, "'eval_freq'"),
}


def _refused(tmp_path, cfg, capsys, monkeypatch, *extra):
    """main's exit code and stderr, with Ray made impossible to start."""

    def no_ray(*a, **k):
        raise AssertionError("Ray was started for a bad sweep file")

    monkeypatch.setattr(S, "_start_ray", no_ray)
    monkeypatch.chdir(tmp_path)
    code = S.main(["--config", str(_write(tmp_path / "sweep.yml", cfg)), *extra])
    return code, capsys.readouterr().err


@pytest.mark.parametrize("case", list(BAD))
def test_bad_grid_file_is_one_line_naming_the_key(case, tmp_path, capsys, monkeypatch):
    change, key = BAD[case]
    cfg = {k: v for k, v in dict(_grid(tmp_path), **change).items() if v is not None}
    code, err = _refused(tmp_path, cfg, capsys, monkeypatch)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and key in err, err
    assert not (tmp_path / "state").exists() and not (tmp_path / "runs").exists()


@pytest.mark.parametrize("case", list(BAD_SEARCH))
def test_bad_search_file_is_one_line_naming_the_key(case, tmp_path, capsys, monkeypatch):
    change, key = BAD_SEARCH[case]
    cfg = {k: v for k, v in dict(SEARCH, **change).items() if v is not None}
    code, err = _refused(tmp_path, cfg, capsys, monkeypatch)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and key in err, err


def test_start_refuses_occupied_run_folders_and_resume_needs_a_sweep(tmp_path, capsys, monkeypatch):
    """A new grid does not train into a run folder that holds files; --resume without a
    saved sweep is refused; both before Ray starts."""
    cfg = _grid(tmp_path)
    code, err = _refused(tmp_path, cfg, capsys, monkeypatch, "--resume")
    assert code == 2 and "--resume: no sweep to resume" in err, err
    (tmp_path / "runs" / "default" / "ppo_seed1").mkdir(parents=True)
    (tmp_path / "runs" / "default" / "ppo_seed1" / "notes.txt").write_text("mine")
    code, err = _refused(tmp_path, cfg, capsys, monkeypatch)
    assert code == 2 and "ppo_seed1" in err and len(err.strip().splitlines()) == 1, err


def test_grid_trials_and_run_folders_follow_agents_train(tmp_path):
    """scenes x agents x seeds, named configurations included, in agents.train's layout."""
    conf = _write(
        tmp_path / "wide.yml",
        {"RollingDrive-v0": {"n_envs": 2, "n_timesteps": 4096, "n_steps": 64, "batch_size": 64}},
    )
    cfg = _grid(
        tmp_path,
        scenes=["default", "loaded"],
        configs={"ppo_wide": {"algo": "ppo", "conf": str(conf)}},
    )
    sweep = S.load_sweep(_write(tmp_path / "sweep.yml", cfg))
    trials = S.grid_trials(sweep)
    assert [t["label"] for t in trials] == [
        f"{s}/{a}_seed{n}"
        for s in ("default", "loaded")
        for a in ("ppo", "ppo_wide")
        for n in (0, 1)
    ]
    assert trials[2]["run_dir"] == str(tmp_path / "runs" / "default" / "ppo_wide_seed0")
    assert trials[2]["conf"] == str(conf) and trials[2]["algo"] == "ppo"


SHIPPED = sorted(p.name for p in (REPO / "configs" / "sweeps").glob("*.yml"))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_sweep_files_pass_the_checks(name):
    sweep = S.load_sweep(REPO / "configs" / "sweeps" / name)
    assert S.grid_trials(sweep) if sweep["kind"] == "grid" else sweep["trials"]


# ------------------------------------------------------------------ sweeps on Ray
@pytest.mark.slow  # its checks are also made by the resumed sweep of the next test
def test_grid_sweep_writes_runs_that_agents_evaluate_reads(tmp_path, ray_tmp):
    """A local two-trial grid (a local Ray instance, as by default) trains both runs into
    runs/<scene>/<algo>_seed<N>/, each with one numba thread, and agents.evaluate reads
    them as they are."""
    pytest.importorskip("ray.tune")
    import rolling_env
    from agents.evaluate import controllers_for

    out = _sweep(tmp_path, _write(tmp_path / "grid.yml", _grid(tmp_path)), ray_tmp=ray_tmp)
    assert out.returncode == 0, out.stdout + out.stderr
    for seed in (0, 1):
        run = tmp_path / "runs" / "default" / f"ppo_seed{seed}"
        meta = json.loads((run / "meta.json").read_text())
        assert meta["env_steps"] >= TINY["n_timesteps"] and meta["interrupted"] is False
        assert meta["threads"]["NUMBA_NUM_THREADS"] == "1", meta["threads"]
        assert (
            (run / "command.txt")
            .read_text()
            .startswith("python -m agents.train --algo ppo --scene default --seed")
        )
        assert f"default/ppo_seed{seed}" in out.stdout  # the summary table
    # what agents.evaluate does before any episode: find, check and load every run
    ctrls = controllers_for("default", tmp_path / "runs", rolling_env.make("default"))
    for seed in (0, 1):
        assert ctrls[f"ppo_seed{seed}"].file == "model.zip", sorted(ctrls)


def test_interrupted_sweep_resumes_without_retraining_finished_trials(tmp_path, ray_head, ray_tmp):
    """A two-trial grid on a cluster (--address), stopped by SIGTERM after the first trial
    finished, while the second trains: exit 143 with the state saved.  --resume, here on a
    local Ray instance (the default), trains only the second trial, from scratch in its run
    folder, and leaves the first run's files untouched; agents.evaluate loads both runs."""
    import rolling_env
    from agents.evaluate import controllers_for

    cfg = _grid(tmp_path, max_concurrent=1, n_timesteps=8192)
    config = _write(tmp_path / "grid.yml", cfg)
    first = tmp_path / "runs" / "default" / "ppo_seed0"
    second = tmp_path / "runs" / "default" / "ppo_seed1"
    proc = subprocess.Popen(
        [sys.executable, "-m", "agents.sweep", "--config", str(config), "--address", ray_head],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=_joined(),
    )
    lines = []
    try:
        for line in proc.stdout:
            lines.append(line)
            if "default/ppo_seed0 finished" in line:
                deadline = time.monotonic() + 60
                while not (second / "config.yml").exists() and time.monotonic() < deadline:
                    time.sleep(0.02)
                proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = "".join(lines)
    assert proc.returncode == 143, text
    assert (first / "model.zip").is_file() and not (second / "model.zip").exists(), text
    assert (second / "config.yml").is_file(), "the second trial had started training"
    kept = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in first.iterdir() if p.is_file()}
    out = _sweep(tmp_path, config, "--resume", ray_tmp=ray_tmp)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "default/ppo_seed0 finished" not in out.stdout, "the finished trial ran again"
    assert "default/ppo_seed1 finished" in out.stdout, out.stdout
    assert {
        p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in first.iterdir() if p.is_file()
    } == kept, "the finished run's files changed"
    meta = json.loads((second / "meta.json").read_text())
    assert meta["interrupted"] is False and meta["env_steps"] >= 8192
    assert meta["threads"]["NUMBA_NUM_THREADS"] == "1", meta["threads"]
    assert (
        (second / "command.txt")
        .read_text()
        .startswith("python -m agents.train --algo ppo --scene default --seed 1")
    )
    assert "2 of 2 trials finished" in out.stdout, out.stdout
    ctrls = controllers_for("default", tmp_path / "runs", rolling_env.make("default"))
    assert {ctrls[f"ppo_seed{n}"].file for n in (0, 1)} == {"model.zip"}, sorted(ctrls)


def test_search_writes_a_best_entry_that_agents_train_trains(tmp_path, ray_head):
    """Optuna + ASHA over three short trials; the best finished trial's entry is written
    to the output file (RL Zoo format, keyed by scene) and trains with agents.train."""
    pytest.importorskip("optuna")
    from agents.train import main as train_main

    best = tmp_path / "tuned" / "ppo.yml"
    cfg = dict(
        SEARCH,
        storage=str(tmp_path / "state"),
        output=str(best),
        eval_freq=2048,
        grace_period=2048,
        reduction_factor=2,
        max_concurrent=2,
        space={
            "learning_rate": {"loguniform": [1.0e-4, 1.0e-3]},
            "n_epochs": {"int": [2, 5]},
            "gamma": {"choice": [0.98, 0.995]},
        },
    )
    out = _sweep(tmp_path, _write(tmp_path / "search.yml", cfg), "--address", ray_head)
    assert out.returncode == 0, out.stdout + out.stderr
    table = yaml.safe_load(best.read_text())
    entry = table["default"]
    assert 1e-4 <= entry["learning_rate"] <= 1e-3 and 2 <= entry["n_epochs"] <= 5
    assert entry["gamma"] in (0.98, 0.995) and entry["n_steps"] == 256  # the base entry's
    tried = [
        yaml.safe_load(p.read_text())["default"]
        for p in (tmp_path / "state" / "s" / "trials").glob("*.hyperparams.yml")
    ]
    assert len(tried) == 3 and entry in tried, "the entry is one that a trial trained"
    assert (
        train_main(
            [
                "--algo",
                "ppo",
                "--scene",
                "default",
                "--conf",
                str(best),
                "--n-timesteps",
                "2048",
                "--eval-freq",
                "100000",
                "--no-progress",
                "--run-dir",
                str(tmp_path / "check"),
            ]
        )
        == 0
    )
    assert (tmp_path / "check" / "model.zip").is_file()
