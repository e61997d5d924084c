"""Baselines and the training/evaluation scripts, run for real (short budgets)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import rolling_env
from agents.baselines import Eq32Design, Eq32Feedback, Eq32OpenLoop
from agents.common import atomic_write, load_hyperparams, parse_kwargs
from agents.evaluate import agent_file, episode_metrics, goal_verdicts, held_out_targets, load_agent
from rolling_env.rollout import rollout

REPO = Path(__file__).resolve().parent.parent


def _final_errors(scene, cls, n):
    env = rolling_env.make(scene)
    ctrl = cls.from_env(env)
    tol = env.unwrapped.scene.tolerance
    return [
        abs(rollout(env, ctrl, seed=i, target=t)["final_error"]) / tol
        for i, t in enumerate(held_out_targets(scene, n))
    ]


def test_open_loop_exact_in_heavy_infinite_friction_scene():
    """Heavy runner, infinite friction: Eq. 32 (with the start-up lag from the impulse slope)
    puts the runner within the scene's tolerance (0.2 um on 2-20 um targets) on every target."""
    errs = _final_errors("heavy_inf_friction", Eq32OpenLoop, 4)
    assert max(errs) < 1.0, f"open-loop final |error| / tolerance: {np.round(errs, 2)}"


@pytest.mark.parametrize("scene", ["default", "resonant", "loaded"])
def test_feedback_at_least_as_good_as_open_loop(scene):
    """Where Eq. 32 is inexact the feedback baseline's mean final error is no worse."""
    fb = np.mean(_final_errors(scene, Eq32Feedback, 4))
    ol = np.mean(_final_errors(scene, Eq32OpenLoop, 4))
    assert fb <= ol, f"{scene}: feedback {fb:.2f} vs open loop {ol:.2f} (x tolerance)"


def test_feedback_stops_at_the_target_in_default_scene():
    """Finite friction, heavy runner: the feedback baseline ends within half the tolerance
    (10 nm on 100-500 nm targets; measured at most 0.3) on every target: it brakes instead of
    overshooting and the stop does not spring back."""
    errs = _final_errors("default", Eq32Feedback, 4)
    assert max(errs) < 0.5, f"feedback final |error| / tolerance: {np.round(errs, 2)}"


def test_baseline_on_a_vecenv_batch_matches_single_env():
    """predict on a VecEnv batch (obs (n, 13), episode_start per env) drives each env as the
    single-env rollout does."""
    from rolling_env.vector import RollingDriveVecEnv

    target = 2e-7
    venv = RollingDriveVecEnv(2, scene="default")
    venv.set_options({"target": target})
    obs = venv.reset()
    ctrl = Eq32Feedback.from_env(venv)
    starts = np.ones(2, bool)
    for _ in range(511):
        act, _ = ctrl.predict(obs, episode_start=starts)
        obs, _, starts, _ = venv.step(act)
    err_batch = obs[:, 0] * venv.get_attr("scene")[0].target_max
    env = rolling_env.make("default")
    single = rollout(env, Eq32Feedback.from_env(env), seed=0, target=target, max_steps=511)
    assert np.allclose(err_batch, single["final_error"], rtol=1e-5, atol=1e-13), (
        err_batch,
        single["final_error"],
    )


def test_design_inverts_eq32_and_stays_wearless():
    env = rolling_env.make("default")
    d = Eq32Design(env.unwrapped.scene)
    for frac in (0.01, 0.2, 0.7, 1.0):
        delta, creep = d.choose(frac * d.v_max)
        assert abs(d.speed(delta, creep) - frac * d.v_max) < 1e-9 * d.v_max
        assert creep <= d.creep_cap * (1 + 1e-12), "creep must stay in the wearless window"
    # the wearless window of physics.md: creep * w * a1 < mu (E*/G*) a1^2 / R
    sc = env.unwrapped.scene
    assert d.creep_cap * d.w * d.a1 < sc.mu * sc.E_star / sc.G_star * d.a1**2 / sc.R
    r = rollout(env, Eq32OpenLoop.from_env(env), seed=0, target=2e-7)
    # mostly stuck: far less friction work than sliding the runner's whole travel at mu N_max.
    # Not none: with finite friction the material leaving the contact slides to zero
    # deflection at the trailing edge, where its friction limit vanishes, dissipating its
    # elastic energy (measured about 12% of that bound)
    assert r["total_slip_work"] < 0.2 * sc.mu * sc.N_max * 2e-7, r["total_slip_work"]


def test_relaxation_time_matches_simulated_lag():
    """t_r from the impulse slope: a runner started at rest lags v_wp t_r once relaxed (15%)."""
    env = rolling_env.make("heavy_inf_friction")
    d = Eq32Design(env.unwrapped.scene)
    delta, creep = d.choose(0.5 * d.v_max)
    v = d.speed(delta, creep)
    tr = d.relaxation_time(delta)
    env.reset(seed=0, options={"target": env.unwrapped.scene.target_max})  # not used by d.action
    x = []
    for k in range(512):
        x.append(env.step(d.action(k, delta, creep, 1))[4]["xstar"])
    t = (np.arange(512) + 1) * env.unwrapped.dt
    lag = np.mean(v * t[-64:] - np.array(x[-64:]))
    assert abs(lag - v * tr) < 0.15 * v * tr, f"lag {lag:.3e} m vs v_wp t_r {v * tr:.3e} m"


def test_batch_predict_matches_single():
    env = rolling_env.make("default")
    ctrl_a, ctrl_b = Eq32Feedback.from_env(env), Eq32Feedback.from_env(env)
    obs = np.tile(env.reset(seed=0, options={"target": 2e-7})[0], (3, 1))
    a_batch, _ = ctrl_a.predict(obs, episode_start=np.ones(3, bool))
    a_one, _ = ctrl_b.predict(obs[0], episode_start=np.array([True]))
    assert a_batch.shape == (3, 3) and np.array_equal(a_batch[1], a_one)


def test_hyperparams_rl_zoo_format():
    for algo in ("ppo", "sac", "td3"):
        hp = load_hyperparams(algo, "resonant")
        assert hp["env_kwargs"]["scene"] == "resonant"
        assert {"n_envs", "n_timesteps", "normalize", "policy_kwargs"} <= set(hp)
        assert isinstance(parse_kwargs(hp["policy_kwargs"]), dict)
    assert load_hyperparams("ppo", "my_scene")["env_kwargs"]["scene"] == "my_scene"


def test_atomic_write_never_leaves_partial_file(tmp_path):
    target = tmp_path / "model.zip"
    target.write_text("old")

    def broken(p):
        Path(p).write_text("half")
        raise RuntimeError("killed mid-write")

    with pytest.raises(RuntimeError):
        atomic_write(target, broken)
    assert target.read_text() == "old" and list(tmp_path.iterdir()) == [target]
    atomic_write(target, lambda p: Path(p).write_text("new"))
    assert target.read_text() == "new"


def test_atomic_write_gives_the_mode_of_a_plain_open(tmp_path):
    """Results are readable like any file the user writes (umask applied), not owner-only; an
    existing file keeps its mode, as open() for writing keeps it."""
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    atomic_write(tmp_path / "atomic.txt", lambda p: Path(p).write_text("x"))
    mode = (tmp_path / "atomic.txt").stat().st_mode & 0o777
    assert mode == plain.stat().st_mode & 0o777, f"{oct(mode)} != plain {oct(plain.stat().st_mode)}"
    for kept in (0o600, 0o640):
        os.chmod(plain, kept)
        atomic_write(plain, lambda p: Path(p).write_text("y"))
        assert plain.stat().st_mode & 0o777 == kept and plain.read_text() == "y"


def test_atomic_write_applies_the_umask(tmp_path, monkeypatch):
    """A new file gets 0666 less the process umask (read once at import), whatever it is."""
    import rolling_env.io as rio

    for mask in (0o022, 0o027, 0o077):
        monkeypatch.setattr(rio, "_UMASK", mask)
        f = tmp_path / f"new{mask:o}.txt"
        atomic_write(f, lambda p: Path(p).write_text("x"))
        assert f.stat().st_mode & 0o777 == 0o666 & ~mask, oct(f.stat().st_mode)


def _train(tmp_path, *extra, timesteps=512, scene="default", n_envs=2):
    cmd = [
        sys.executable,
        "-m",
        "agents.train",
        "--algo",
        "ppo",
        "--scene",
        scene,
        "--seed",
        "3",
        "--n-timesteps",
        str(timesteps),
        "--n-envs",
        str(n_envs),
        "--eval-freq",
        "512",
        "--eval-episodes",
        "1",
        "--no-progress",
        "--run-dir",
        str(tmp_path / "run"),
        *extra,
    ]
    return cmd


def test_short_training_run_saves_loadable_model(tmp_path):
    out = subprocess.run(_train(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    run = tmp_path / "run"
    for f in (
        "model.zip",
        "model_vecnormalize.pkl",
        "config.yml",
        "command.txt",
        "meta.json",
        "evaluations.npz",
        "best_model.zip",
        "best_model_vecnormalize.pkl",
    ):
        assert (run / f).exists(), f"missing {f}"
    meta = json.loads((run / "meta.json").read_text())
    assert meta["env_steps"] >= 512 and meta["seed"] == 3 and not meta["interrupted"]
    command = (run / "command.txt").read_text()
    assert command.startswith("python -m agents.train --algo ppo --scene default"), command
    head = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True
    )
    if head.returncode == 0:  # a git checkout: the run records the code that trained it
        assert meta["commit"].split("-")[0] == head.stdout.strip(), meta["commit"]
    assert set(meta["threads"]) == {"NUMBA_NUM_THREADS", "OMP_NUM_THREADS"}, meta
    env = rolling_env.make("default")
    agent = load_agent(run / "model.zip", env)
    data = rollout(env, agent, seed=0, target=2e-7)
    m = episode_metrics(data, env.unwrapped.scene.tolerance)
    assert np.isfinite(m["final_abs_error"]) and len(data["step"]) == 512
    assert agent_file(run) == run / "model.zip", "the final model is evaluated by default"
    assert agent_file(run, "best") == run / "best_model.zip"  # its statistics saved with it
    assert not [p for p in run.iterdir() if p.name.startswith(".")], "scratch files left behind"
    # the periodic evaluations' final errors and slip work, one entry per evaluation
    log = json.loads((run / "eval_goal.json").read_text())
    with np.load(run / "evaluations.npz") as ev:
        assert [e["env_steps"] for e in log] == ev["timesteps"].tolist()
    sc = env.unwrapped.scene
    for e in log:
        assert len(e["final_abs_error"]) == len(e["slip_work"]) == 1  # --eval-episodes 1
        assert 0 <= e["final_abs_error"][0] <= 2 * sc.target_max, e
        assert e["slip_work"][0] > 0, "finite friction: the evaluation episode slides"
        assert e["wall_seconds"] > 0


def test_train_refuses_a_used_run_folder(tmp_path, capsys):
    """A second run into a folder that holds a run is refused before anything is written (it
    mixed its files with the first's and overwrote an interrupted run's checkpoint).
    --overwrite replaces only a folder this script created (marker) holding only its files:
    never one with foreign, hidden or extra TensorBoard files, a symlink, or the working
    folder's parents (it once deleted whatever --run-dir named)."""
    import shutil

    from agents.train import RUN_MARKER
    from agents.train import main as train_main

    run = tmp_path / "run"
    run.mkdir()
    inode = run.stat().st_ino
    argv = [
        "--algo",
        "ppo",
        "--n-timesteps",
        "64",
        "--n-envs",
        "1",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "1",
        "--no-progress",
    ]
    assert train_main(argv + ["--run-dir", str(run), "--overwrite"]) == 0
    assert run.stat().st_ino == inode, "an empty folder must be used, not deleted and remade"
    assert (run / RUN_MARKER).is_file() and (run / "model.zip").exists()
    assert train_main(argv + ["--run-dir", str(run)]) == 2
    assert "already exists and is not empty" in capsys.readouterr().err
    good = tmp_path / "good"
    shutil.copytree(run, good)
    assert train_main(argv + ["--run-dir", str(run), "--overwrite"]) == 0  # its own files only
    for extra, reason in (
        (".env", "holds files a run does not write (.env)"),
        ("notes.txt", "holds files a run does not write (notes.txt)"),
        ("tb/mydata/paper.tex", "tb/mydata"),
    ):
        victim = tmp_path / "victim"
        shutil.copytree(good, victim)
        (victim / extra).parent.mkdir(parents=True, exist_ok=True)
        (victim / extra).write_text("keep me")
        assert train_main(argv + ["--run-dir", str(victim), "--overwrite"]) == 2, extra
        err = capsys.readouterr().err
        assert reason in err and "nothing was deleted" in err, err
        assert (victim / extra).read_text() == "keep me"
        shutil.rmtree(victim)
    (good / RUN_MARKER).unlink()  # e.g. a folder with a config.yml of its own
    assert train_main(argv + ["--run-dir", str(good), "--overwrite"]) == 2
    assert f"has no {RUN_MARKER} marker" in capsys.readouterr().err
    (good / RUN_MARKER).write_text("x")
    link = tmp_path / "link"
    link.symlink_to(good)
    assert train_main(argv + ["--run-dir", str(link), "--overwrite"]) == 2
    assert "is a symbolic link" in capsys.readouterr().err
    os.chdir(good / "tb")
    try:
        assert train_main(argv + ["--run-dir", str(good), "--overwrite"]) == 2
        assert "one of its parents" in capsys.readouterr().err
    finally:
        os.chdir(REPO)
    assert (good / "model.zip").exists()


def test_time_to_goal_is_the_first_evaluation_that_meets_the_goal():
    from agents.evaluate import time_to_goal

    base = {"final_abs_error_mean": 1.0e-8, "slip_work_mean": 2.0e-8}
    log = [
        {
            "env_steps": 10,
            "wall_seconds": 1.0,
            "final_abs_error": [4e-9, 8e-9],
            "slip_work": [1e-8, 1e-8],
        },  # error 0.6x: not yet
        {
            "env_steps": 20,
            "wall_seconds": 2.0,
            "final_abs_error": [4e-9, 5e-9],
            "slip_work": [3e-8, 2e-8],
        },  # error 0.45x, but 1.25x the wear
        {
            "env_steps": 30,
            "wall_seconds": 3.5,
            "final_abs_error": [4e-9, 6e-9],
            "slip_work": [2e-8, 2e-8],
        },  # 0.5x at 1x: met
        {"env_steps": 40, "wall_seconds": 4.0, "final_abs_error": [1e-9], "slip_work": [1e-8]},
    ]
    assert time_to_goal(log, base) == (30, 3.5)
    assert time_to_goal(log[:2], base) == "never"
    assert time_to_goal(None, base) is None


def test_goal_verdicts():
    rows = [
        dict(scene="s", controller="eq32-open-loop", final_abs_error_mean=4.0, slip_work_mean=1.0),
        dict(scene="s", controller="eq32-feedback", final_abs_error_mean=2.0, slip_work_mean=3.0),
        dict(scene="s", controller="ppo_seed0", final_abs_error_mean=0.9, slip_work_mean=3.0),
        dict(scene="s", controller="sac_seed0", final_abs_error_mean=0.9, slip_work_mean=3.1),
    ]
    v = {r["agent"]: r for r in goal_verdicts(rows)}
    assert v["ppo_seed0"]["baseline"] == "eq32-feedback" and v["ppo_seed0"]["met"]
    assert not v["sac_seed0"]["met"], "more slip work than the baseline is not the goal"


def test_seed_summary_sums_up_runs_that_differ_only_in_their_seed():
    """ppo_seed0..2 are one configuration over three seeds: the mean of the runs' means, their
    range, and the goal met in 2 of 3 (seed 2 has more slip work than the baseline); sac_seed0
    alone and a run not named <name>_seed<N> get no summary row."""
    from agents.evaluate import seed_summary

    def row(c, err, slip):
        return dict(
            scene="s",
            controller=c,
            final_abs_error_mean=err * 1e-8,
            slip_work_mean=slip,
            tolerance=1e-8,
        )

    rows = [
        row("eq32-open-loop", 4.0, 1.0),
        row("eq32-feedback", 2.0, 3.0),
        row("ppo_seed0", 0.5, 2.0),
        row("ppo_seed1", 0.9, 3.0),
        row("ppo_seed2", 1.0, 4.0),
        row("sac_seed0", 0.1, 0.0),
        row("myrun", 0.1, 0.0),
    ]
    (g,) = seed_summary(rows)
    assert (g["agent"], g["seeds"], g["seed_list"]) == ("ppo", 3, [0, 1, 2]), g
    assert g["error_mean"] == pytest.approx(0.8, rel=1e-12), g
    assert (g["error_min"], g["error_max"]) == pytest.approx((0.5, 1.0), rel=1e-12), g
    assert g["slip_mean"] == pytest.approx(3.0, rel=1e-12), g
    assert (g["met"], g["judged"]) == (2, 3), f"goal met in seeds 0 and 1 only: {g}"
    # two runs naming one seed (ppo_seed1, ppo_seed01) are not two seeds
    assert seed_summary(rows + [row("ppo_seed01", 0.7, 2.0)]) == []
    # an interrupted run (its checkpoint, fewer steps) or another configuration is not a seed
    for key, value in (
        ("model_file", "checkpoint.zip"),
        ("train_env_steps", 20_000),
        ("config_key", '{"n_timesteps": 1000}'),
    ):
        other = [dict(r, **{key: value}) if r["controller"] == "ppo_seed1" else r for r in rows]
        assert seed_summary(other) == [], f"runs with another {key} were summed up over seeds"


def _sigint_as_in_a_terminal():
    """preexec_fn: Ctrl-C reaches the child as it does from an interactive shell (a
    background job of a non-interactive shell, a CI runner's, ignores SIGINT, and children
    inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_interrupted_training_leaves_loadable_checkpoint(tmp_path, sig):
    proc = subprocess.Popen(
        _train(tmp_path, timesteps=10**7),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_sigint_as_in_a_terminal,
    )
    run = tmp_path / "run"
    deadline = time.time() + 120
    while not (run / "evaluations.npz").exists() and time.time() < deadline:
        time.sleep(0.5)
    proc.send_signal(sig)
    proc.wait(timeout=120)
    assert proc.returncode == 128 + sig, "an interrupted run must exit 128 + signal, not 0"
    meta = json.loads((run / "meta.json").read_text())
    assert meta["interrupted"] and (run / "checkpoint.zip").exists()
    env = rolling_env.make("default")
    agent = load_agent(run / "checkpoint.zip", env)
    obs, _ = env.reset(seed=0)
    a, _ = agent.predict(obs)
    assert env.action_space.contains(np.asarray(a, np.float32))
    assert not [p for p in run.iterdir() if p.name.startswith(".")], "temp files left behind"


@pytest.mark.slow
def test_ppo_learns_to_move_the_runner(tmp_path):
    """Slow (about 1 min on 2 cores): 400k PPO steps (8 envs, the YAML's settings) on the
    heavy infinite-friction scene at least halve the final error of standing still (|target|)
    on the median held-out target.  The shipped 1M-step run's learning curve leaves its plateau
    of about -300 at 200-300k steps."""
    out = subprocess.run(
        _train(
            tmp_path,
            "--eval-freq",
            "50000",
            timesteps=400_000,
            scene="heavy_inf_friction",
            n_envs=8,
        ),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=3000,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    env = rolling_env.make("heavy_inf_friction")
    agent = load_agent(tmp_path / "run" / "model.zip", env)
    targets = held_out_targets("heavy_inf_friction", 5)
    rel = [
        abs(rollout(env, agent, seed=i, target=t)["final_error"] / t) for i, t in enumerate(targets)
    ]
    # the median: one short run may still send a single target astray (seen: 1 of 5)
    assert np.median(rel) < 0.5, f"PPO final |error| / |target|: {np.round(rel, 3)}"


@pytest.mark.parametrize(
    "extra,name",
    [
        (["--n-timesteps", "0"], "n-timesteps"),
        (["--n-timesteps", "-5"], "n-timesteps"),
        (["--n-envs", "0"], "n-envs"),
        (["--eval-freq", "-1"], "eval-freq"),
        (["--seed", "-3"], "seed"),
    ],
)
def test_train_rejects_bad_arguments(extra, name, tmp_path, capsys):
    """No silent fallback to the YAML budget, no clamping: exit 2 naming the argument."""
    from agents.train import main as train_main

    with pytest.raises(SystemExit) as e:
        train_main(["--algo", "ppo", "--run-dir", str(tmp_path / "run"), *extra])
    assert e.value.code == 2
    assert name in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_train_bad_scene_leaves_no_run_folder(tmp_path, capsys):
    from agents.train import main as train_main

    assert (
        train_main(["--algo", "ppo", "--scene", "bogus", "--run-dir", str(tmp_path / "run")]) == 2
    )
    err = capsys.readouterr().err
    assert "--scene: unknown scene 'bogus'" in err, err
    assert not (tmp_path / "run").exists(), "config.yml written before the scene was checked"


def test_rollout_takes_the_open_loop_baseline_by_its_table_name():
    """``eq32-open-loop`` (the name in agents.evaluate's tables) is the same controller as
    ``eq32``: the same class and an identical 40-step rollout."""
    from rolling_env.rollout import make_controller

    data = {}
    for name in ("eq32", "eq32-open-loop"):
        env = rolling_env.make("default")
        ctrl = make_controller(name, env)
        assert isinstance(ctrl, Eq32OpenLoop), f"{name}: {type(ctrl).__name__}"
        data[name] = rollout(env, ctrl, seed=5, max_steps=40)
    a, b = data["eq32"], data["eq32-open-loop"]
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k]), err_msg=k)


@pytest.mark.filterwarnings("ignore:You have specified a mini-batch size")
@pytest.mark.parametrize(
    "field, value",
    [
        ("batch_size", 0),
        ("learning_rate", "abc"),
        ("policy_kwargs", "dict(net_arch=[64"),
        ("n_steps", 2.5),
        ("normalize", "dict(foo=1)"),
    ],
)
def test_train_bad_hyperparameters_are_usage_errors(field, value, tmp_path, capsys):
    """Hyper-parameters that SB3 rejects (by assert, TypeError or a syntax error in a kwargs
    string) are one line and exit 2 with no run folder, like a bad scene."""
    from agents.train import main as train_main

    conf = yaml.safe_load((REPO / "configs/hyperparams/ppo.yml").read_text())
    conf["default"][field] = value
    path = tmp_path / "ppo.yml"
    path.write_text(yaml.safe_dump(conf))
    assert (
        train_main(
            [
                "--algo",
                "ppo",
                "--conf",
                str(path),
                "--run-dir",
                str(tmp_path / "run"),
                "--n-timesteps",
                "64",
                "--no-progress",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("python -m agents.train: error:") and err.count("\n") == 1, err
    assert not (tmp_path / "run").exists()
    assert (
        train_main(
            [
                "--algo",
                "ppo",
                "--conf",
                str(tmp_path / "missing.yml"),
                "--run-dir",
                str(tmp_path / "run"),
            ]
        )
        == 2
    )
    assert "missing.yml" in capsys.readouterr().err
    del conf["default"]["n_timesteps"]
    path.write_text(yaml.safe_dump({"default": conf["default"]}))
    assert (
        train_main(["--algo", "ppo", "--conf", str(path), "--run-dir", str(tmp_path / "run")]) == 2
    )
    assert "'n_timesteps' missing" in capsys.readouterr().err
    path.write_text(yaml.safe_dump({"other": conf["default"]}))
    assert (
        train_main(["--algo", "ppo", "--conf", str(path), "--run-dir", str(tmp_path / "run")]) == 2
    )
    assert "needs an entry for scene 'default'" in capsys.readouterr().err


def test_train_lets_an_error_while_learning_propagate(tmp_path, monkeypatch):
    """Only a usage error (scene, hyper-parameter, argument) becomes a one-line exit 2; a
    ValueError raised while learning keeps its traceback."""
    import stable_baselines3 as sb3

    from agents.train import main as train_main

    def boom(self, *a, **k):
        raise ValueError("raised inside learn")

    monkeypatch.setattr(sb3.PPO, "learn", boom)
    with pytest.raises(ValueError, match="raised inside learn"):
        train_main(
            [
                "--algo",
                "ppo",
                "--run-dir",
                str(tmp_path / "run"),
                "--n-timesteps",
                "64",
                "--no-progress",
            ]
        )


def test_evaluate_checks_every_scene_before_writing(tmp_path, capsys):
    from agents.evaluate import main as evaluate_main

    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                "heavy_inf_friction",
                "bogus",
                "--runs",
                str(tmp_path),
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "out"),
            ]
        )
    assert e.value.code == 2 and "bogus" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_train_scene_key_accepts_both_yaml_suffixes():
    from agents.train import scene_key

    assert scene_key("configs/scenes/resonant.yml") == scene_key("x/resonant.yaml") == "resonant"
    assert scene_key("default") == "default"


@pytest.mark.parametrize("cls", [Eq32OpenLoop, Eq32Feedback])
def test_baseline_restarts_on_a_reset_observation_without_episode_start(cls):
    """A plain Gymnasium loop that never passes episode_start: the second episode must be
    driven like the first (the reset observation's time_fraction = 0 restarts the plan)."""
    env = rolling_env.make("heavy_inf_friction")
    tol = env.unwrapped.scene.tolerance
    reused = cls.from_env(env)
    finals = {}
    for ep in (0, 1):
        for name, ctrl in (("reused", reused), ("fresh", cls.from_env(env))):
            obs, _ = env.reset(seed=ep)
            done = False
            while not done:
                obs, _, te, tr, info = env.step(ctrl.predict(obs)[0])
                done = te or tr
            finals[name, ep] = abs(info["target"] - info["xstar"])
    for ep in (0, 1):
        assert finals["reused", ep] == pytest.approx(finals["fresh", ep], abs=1e-3 * tol), (
            f"episode {ep}: reused controller ends {finals['reused', ep] / tol:.2f} tol off, "
            f"fresh one {finals['fresh', ep] / tol:.2f}"
        )


def test_baseline_rejects_a_scene_too_slow_for_eq32():
    """w = W/a1 >= 2 is impossible with a small rolling-rate limit: a clear error at
    construction naming the limit, not a failure mid-episode."""
    env = rolling_env.make("default", omega_R_max=0.1)
    with pytest.raises(ValueError, match=r"omega_R_max = 0.1 m/s allows w = 0.134"):
        Eq32Feedback.from_env(env)
    with pytest.raises(ValueError, match="stroke_roll"):
        Eq32OpenLoop.from_env(rolling_env.make("default", stroke_roll=1e-5))
    for kw, name in (
        (dict(w_pref=1.9), "w_pref"),
        (dict(slip_margin=0.0), "slip_margin"),
        (dict(delta_pref=1.5), "delta_pref"),
        (dict(delta_pref=1.0), "delta_pref"),
    ):
        with pytest.raises(ValueError, match=name):
            Eq32Feedback.from_env(rolling_env.make("default"), **kw)


def test_evaluate_rejects_a_scene_the_baselines_cannot_drive(tmp_path, capsys):
    """A valid scene file that Eq. 32 cannot drive (w < 2) is refused before anything is
    written, not after the other scenes were evaluated."""
    from agents.evaluate import main as evaluate_main

    slow = tmp_path / "slow.yaml"
    data = yaml.safe_load((rolling_env.scenes.SCENE_DIR / "default.yaml").read_text())
    slow.write_text(yaml.safe_dump({**data, "omega_R_max": 0.1}))
    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                "heavy_inf_friction",
                str(slow),
                "--runs",
                str(tmp_path),
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "out"),
            ]
        )
    assert e.value.code == 2 and "omega_R_max" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """One tiny PPO run on a scene *file* (copy of heavy_inf_friction named 'myscene')."""
    from agents.train import main as train_main

    base = tmp_path_factory.mktemp("evalruns")
    scene = base / "scenes" / "myscene.yaml"
    scene.parent.mkdir()
    scene.write_text((rolling_env.scenes.SCENE_DIR / "heavy_inf_friction.yaml").read_text())
    runs = base / "runs"
    assert (
        train_main(
            [
                "--algo",
                "ppo",
                "--scene",
                str(scene),
                "--n-timesteps",
                "64",
                "--n-envs",
                "1",
                "--eval-freq",
                "64",
                "--eval-episodes",
                "1",
                "--no-progress",
                "--run-dir",
                str(runs / "myscene" / "ppo_seed0"),
            ]
        )
        == 0
    )
    return scene, runs


def test_evaluate_finds_the_runs_of_a_scene_file(trained_run, tmp_path):
    """A scene given as a file: its runs live under <runs>/<stem>/ (where train puts them) and
    its plot goes to <out>/plots/<stem>.png, not beside the scene file."""
    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    out = tmp_path / "out"
    assert (
        evaluate_main(
            ["--scenes", str(scene), "--runs", str(runs), "--episodes", "1", "--out", str(out)]
        )
        == 0
    )
    text = (out / "comparison.csv").read_text()
    assert "ppo_seed0" in text, f"the trained agent was not evaluated:\n{text}"
    assert (out / "plots" / "myscene.png").exists()
    assert sorted(p.name for p in scene.parent.iterdir()) == ["myscene.yaml"]


def test_evaluate_model_choice_and_seed_summary(trained_run, tmp_path, capsys):
    """--model final (the default) evaluates model.zip and --model best best_model.zip, and the
    table names the file of each row; two seeds of one configuration get an "Over seeds"
    row (here the same model twice: its range is one value).  A run folder without a model
    (an interrupted run whose checkpoint was not copied) is named in a warning, not dropped
    silently; run folders are listed in the order of their numbers (seed 2 before 10)."""
    import shutil

    from agents.evaluate import main as evaluate_main
    from agents.evaluate import scene_runs

    scene, runs = trained_run
    mine = tmp_path / "runs"
    shutil.copytree(runs, mine)
    shutil.copytree(mine / "myscene" / "ppo_seed0", mine / "myscene" / "ppo_seed1")
    (mine / "myscene" / "ppo_seed10").mkdir()
    shutil.copy(mine / "myscene" / "ppo_seed0" / "config.yml", mine / "myscene" / "ppo_seed10")
    assert [p.name for p in scene_runs(str(scene), mine)] == [
        "ppo_seed0",
        "ppo_seed1",
        "ppo_seed10",
    ]
    for model, name in (("final", "model.zip"), ("best", "best_model.zip")):
        out = tmp_path / model
        argv = ["--scenes", str(scene), "--runs", str(mine), "--episodes", "2", "--out", str(out)]
        assert evaluate_main(argv + ([] if model == "final" else ["--model", model])) == 0
        err = capsys.readouterr().err
        assert "ppo_seed10 has no model" in err and "not evaluated" in err, err
        with open(out / "comparison.csv") as f:
            rows = {r["controller"]: r for r in csv.DictReader(f)}
        assert rows["ppo_seed0"]["model_file"] == name, f"--model {model}: {rows['ppo_seed0']}"
        md = (out / "comparison.md").read_text()
        assert f"| myscene | ppo_seed1 | {name} |" in md, md
        (line,) = [ln for ln in md.splitlines() if ln.startswith("| myscene | ppo | 0, 1 |")]
        e0 = float(rows["ppo_seed0"]["final_abs_error_mean"]) / float(
            rows["ppo_seed0"]["tolerance"]
        )
        assert f"| {e0:.2f} ({e0:.2f}-{e0:.2f}) |" in line, f"mean and range of one value: {line}"


@pytest.mark.parametrize(
    "edit,match",
    [
        (
            lambda c: c.update(env_kwargs={"scene": "x", "mu": 0.02}),
            r"scene overrides \{'mu': 0.02\}",
        ),
        (
            lambda c: c.update(scene="resonant", scene_key="resonant"),
            "was trained on scene 'resonant'",
        ),
        (
            lambda c: (c.update(scene="resonant"), c.pop("scene_key")),  # a run from before the key
            "was trained on scene 'resonant'",
        ),
    ],
)
def test_evaluate_refuses_runs_not_trained_on_the_scene(trained_run, tmp_path, capsys, edit, match):
    """A run trained with scene overrides, or on another scene, is refused (naming it) before
    any episode runs or any file is written; it was reported as if trained on the plain
    scene."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    mine = tmp_path / "runs" / "myscene"
    shutil.copytree(runs / "myscene", mine)
    cfg_path = mine / "ppo_seed0" / "config.yml"
    cfg = yaml.safe_load(cfg_path.read_text())
    edit(cfg)
    cfg_path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                str(scene),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(out),
            ]
        )
    assert e.value.code == 2
    assert len(__import__("re").findall(match, capsys.readouterr().err)) == 1
    assert not [p for p in out.rglob("*") if p.is_file()], "files written before the check"


def test_mismatched_model_and_statistics_are_refused(trained_run, tmp_path, capsys):
    """A model and VecNormalize statistics saved at different steps (a kill between the two
    writes of save_model) are refused by load_agent, naming both files; evaluate then falls
    back to the run's next model, with a warning."""
    import shutil

    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from agents.common import SAVED_AT
    from agents.evaluate import controllers_for

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    for f in run.glob("best_model*"):
        f.unlink()
    env = rolling_env.make(str(scene))
    load_agent(run / "model.zip", env)  # a consistent pair loads
    shutil.copy(run / "model.zip", run / "checkpoint.zip")  # a consistent fallback
    shutil.copy(run / "model_vecnormalize.pkl", run / "checkpoint_vecnormalize.pkl")
    stats = run / "model_vecnormalize.pkl"
    vn = VecNormalize.load(str(stats), DummyVecEnv([lambda: rolling_env.make(str(scene))]))
    setattr(vn, SAVED_AT, getattr(vn, SAVED_AT) + 1)  # as if saved one step later
    vn.save(str(stats))
    with pytest.raises(ValueError, match="model_vecnormalize.pkl was saved at step"):
        load_agent(run / "model.zip", env)
    ctrls = controllers_for(str(scene), tmp_path / "runs", env)
    assert ctrls["ppo_seed0"].file == "checkpoint.zip"
    assert "trying checkpoint.zip" in capsys.readouterr().err
    (run / "checkpoint.zip").unlink()
    with pytest.raises(ValueError, match="model_vecnormalize.pkl was saved at step"):
        controllers_for(str(scene), tmp_path / "runs", env)  # nothing left to fall back to


def _scene_file(path, base="default", **changes):
    data = yaml.safe_load((rolling_env.scenes.SCENE_DIR / f"{base}.yaml").read_text())
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump({**data, **changes}))
    return path


def test_custom_scene_file_named_like_a_shipped_one_is_not_taken_for_it(
    tmp_path, monkeypatch, capsys
):
    """A scene file named default.yaml with other content (mu 0.01, runner_mass 1e-4) was
    trained into runs/default/, recorded as env_kwargs {scene: default} and evaluated as a
    `default` agent: it gets its own key default-<digest8>, its config records the scene's
    fields and digest, and evaluate refuses it on the shipped default (by key, and by
    content where the key was edited by hand)."""
    import shutil

    from agents.common import scene_digest, scene_key
    from agents.evaluate import main as evaluate_main
    from agents.train import main as train_main

    custom = _scene_file(tmp_path / "mine" / "default.yaml", mu=0.01, runner_mass=1e-4)
    key = scene_key(str(custom))
    assert key == f"default-{scene_digest(custom)[:8]}", key
    assert scene_key(str(rolling_env.scenes.SCENE_DIR / "default.yaml")) == "default", (
        "the shipped file itself keeps its name"
    )
    monkeypatch.chdir(tmp_path)
    assert (
        train_main(
            [
                "--algo",
                "ppo",
                "--scene",
                str(custom),
                "--n-timesteps",
                "64",
                "--n-envs",
                "1",
                "--eval-freq",
                "64",
                "--eval-episodes",
                "1",
                "--no-progress",
            ]
        )
        == 0
    )
    assert not (tmp_path / "runs" / "default").exists(), "landed in runs/default/ silently"
    run = tmp_path / "runs" / key / "ppo_seed0"
    cfg = yaml.safe_load((run / "config.yml").read_text())
    assert cfg["scene_key"] == key and cfg["scene_digest"] == scene_digest(custom), cfg
    assert cfg["scene_fields"]["mu"] == 0.01 and cfg["scene_fields"]["runner_mass"] == 1e-4
    assert cfg["env_kwargs"] == {"scene": str(custom)}, (
        f"config.yml must name the scene file trained on, got {cfg['env_kwargs']}"
    )
    shutil.copytree(run, tmp_path / "runs" / "default" / "ppo_seed0")  # moved by hand
    argv = [
        "--scenes",
        "default",
        "--runs",
        str(tmp_path / "runs"),
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "out"),
    ]
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and f"was trained on scene {key!r}" in err, err
    moved = tmp_path / "runs" / "default" / "ppo_seed0" / "config.yml"
    moved.write_text(yaml.safe_dump(dict(cfg, scene_key="default")))  # the key edited too
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err and "mu 0.01 vs 0.2" in err, err
    assert not (tmp_path / "out" / "comparison.csv").exists()


def test_evaluate_refuses_a_run_whose_scene_file_changed(trained_run, tmp_path, capsys):
    """The scene file a run was trained on, edited afterwards (same stem, same folder
    layout): refused naming the key that changed, not evaluated as if trained on it."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    shutil.copytree(runs, tmp_path / "runs")
    edited = _scene_file(
        tmp_path / "scenes" / "myscene.yaml", base="heavy_inf_friction", runner_mass=0.01
    )
    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                str(edited),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "out"),
            ]
        )
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err and "runner_mass" in err, err


def _as_if_trained_on(run, **changes):
    """Rewrite a run's config.yml as agents.train would have written it on the scene with
    ``changes`` to its recorded fields (a key given as None left out, as a run recorded
    before the key existed): fields and their digest."""
    from agents.common import fields_digest

    cfg_path = run / "config.yml"
    cfg = yaml.safe_load(cfg_path.read_text())
    fields = dict(cfg["scene_fields"])
    for k, v in changes.items():
        if v is None:
            fields.pop(k, None)
        else:
            fields[k] = v
    cfg.update(scene_fields=fields, scene_digest=fields_digest(fields))
    cfg_path.write_text(yaml.safe_dump(cfg))
    return cfg


def test_numerics_of_a_recorded_scene_are_completed_and_described():
    """A run recorded before a scene key existed (``accuracy``, ``n_sub``, ``grid_levels``) is
    read with the value in effect then (the key's default; the recorded sub_steps for n_sub;
    one fixed grid, 0 levels): no difference where nothing else changed; the note names what
    differs in the numerics, the resolved sub-steps too; the shipped scenes record the
    sub-steps they resolve to."""
    from agents.common import completed_fields, numerics_note, scene_fields

    now = scene_fields("heavy_inf_friction")
    n = rolling_env.scenes.load_scene("heavy_inf_friction").n_sub
    assert now["sub_steps"] == "auto" and now["n_sub"] == n and now["accuracy"] == 0.01, now
    assert now["resolution"] == 64, "the notes below assume 64 cells per radius"
    assert now["grid_levels"] == 4, "the notes below assume 4 grid levels"
    old = {k: v for k, v in now.items() if k not in ("accuracy", "n_sub")}
    before_levels = {k: v for k, v in old.items() if k != "grid_levels"}
    assert completed_fields(dict(before_levels, sub_steps="auto"))["grid_levels"] == 0
    assert (
        numerics_note(completed_fields(dict(before_levels, sub_steps="auto", n_sub=n)), now)
        == "grid_levels 0 (now 4)"
    )
    assert completed_fields(dict(old, sub_steps="auto"))["accuracy"] == 0.01
    assert numerics_note(completed_fields(dict(old, sub_steps=8)), now) == (
        f"sub_steps 8 (now auto: {n})"
    )
    assert numerics_note(completed_fields(dict(now)), now) == ""
    assert numerics_note(
        completed_fields(dict(old, sub_steps=n + 1, resolution=32.0, accuracy=0.05)), now
    ) == (f"sub_steps {n + 1} (now auto: {n}), resolution 32 (now 64), accuracy 0.05 (now 0.01)")


def test_a_run_trained_on_other_numerics_is_evaluated_and_marked(trained_run, tmp_path, capsys):
    """A run whose recorded scene differs from the evaluated one only in its numerics
    (sub_steps, resolution, accuracy; recorded before accuracy and n_sub existed, as the
    committed runs were) is evaluated as it is, and every place that reports it says so:
    a warning, the CSV's trained_numerics, a footnote mark in the three tables with the note
    under the first, and the plot's legend.  `rolling-drive rollout` takes its model too."""
    import shutil

    from agents.evaluate import main as evaluate_main
    from rolling_env.cli import main as cli_main

    scene, runs = trained_run
    shutil.copytree(runs / "myscene" / "ppo_seed0", tmp_path / "runs" / "myscene" / "ppo_seed0")
    shutil.copytree(runs / "myscene" / "ppo_seed0", tmp_path / "runs" / "myscene" / "ppo_seed1")
    for seed in (0, 1):
        _as_if_trained_on(
            tmp_path / "runs" / "myscene" / f"ppo_seed{seed}",
            sub_steps=4,
            resolution=12.0,
            accuracy=None,
            n_sub=None,
        )
    sc = rolling_env.scenes.load_scene(str(scene))
    assert sc.sub_steps == "auto" and sc.n_sub != 4 and sc.resolution == 64
    out = tmp_path / "out"
    assert (
        evaluate_main(
            [
                "--scenes",
                str(scene),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    note = f"sub_steps 4 (now auto: {sc.n_sub}), resolution 12 (now 64)"
    err = capsys.readouterr().err
    assert err.count("trained on other numerics or reward weights") == 2 and note in err, err
    with open(out / "comparison.csv") as f:
        rows = {r["controller"]: r for r in csv.DictReader(f)}
    assert rows["ppo_seed0"]["trained_numerics"] == note, rows["ppo_seed0"]
    assert rows["eq32-feedback"]["trained_numerics"] == "", "a baseline is never marked"
    md = (out / "comparison.md").read_text()
    assert "| myscene | ppo_seed0 [1] | model.zip |" in md, md
    assert f"* [1] trained on other numerics or reward weights: {note}\n" in md, md
    assert "| myscene | ppo_seed1 [1] | eq32-open-loop |" in md, "goal table not marked"
    assert "| myscene | ppo [1] | 0, 1 |" in md, "seed summary not marked"
    assert "| myscene | eq32-feedback | - |" in md
    assert (out / "plots" / "myscene.png").stat().st_size > 0
    model = tmp_path / "runs" / "myscene" / "ppo_seed0" / "model.zip"
    assert (
        cli_main(
            [
                "rollout",
                "--scene",
                str(scene),
                "--controller",
                str(model),
                "--out",
                str(tmp_path / "roll"),
                "--json",
            ]
        )
        == 0
    )
    assert "trained on other numerics" in capsys.readouterr().err


def test_a_run_trained_with_other_reward_weights_is_evaluated_and_marked(
    trained_run, tmp_path, capsys
):
    """The reward's weights shape learning, not what the comparison scores: a run trained
    with ``w_final`` in its env_kwargs (and so in its recorded fields) is evaluated on the
    plain scene and its note names the weight."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    cfg = _as_if_trained_on(run, w_final=10.0)
    (run / "config.yml").write_text(
        yaml.safe_dump(dict(cfg, env_kwargs=dict(cfg["env_kwargs"], w_final=10.0)))
    )
    out = tmp_path / "out"
    assert (
        evaluate_main(
            [
                "--scenes",
                str(scene),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    md = (out / "comparison.md").read_text()
    assert "* [1] trained on other numerics or reward weights: w_final 10 (now 0)\n" in md, md
    assert "| myscene | ppo_seed0 [1] | model.zip |" in md, md
    capsys.readouterr()


@pytest.mark.parametrize(
    "changes,names",
    [
        ({"sub_steps": 4, "mu": 0.3}, ["mu 0.3 vs inf", "sub_steps 4 vs 'auto'"]),  # physics too
        ({"resolution": 12.0, "episode_steps": 256}, ["episode_steps 256 vs 512"]),  # the task
        ({"resolution": 12.0, "ticks_per_period": 16}, ["ticks_per_period 16 vs 8"]),
    ],
)
def test_a_run_trained_on_other_physics_or_task_stays_refused(
    trained_run, tmp_path, capsys, changes, names
):
    """A recorded scene that differs in a physics or task key is refused as before (exit 2,
    the keys named with the physics first, nothing written), also where its numerics differ
    too; so is a record whose fields do not reproduce its digest (edited by hand: its fields
    cannot be trusted key by key)."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    cfg = _as_if_trained_on(run, **changes)
    argv = [
        "--scenes",
        str(scene),
        "--runs",
        str(tmp_path / "runs"),
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "out"),
    ]
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err and "not comparable" in err, err
    assert "trained on other numerics" not in err, err
    trained_vs_now = err.split("trained vs now: ")[1]
    for n in names:
        assert n in trained_vs_now, err
    numerics_key = "resolution" if "resolution" in changes else "sub_steps"
    assert trained_vs_now.index(names[0]) < trained_vs_now.index(numerics_key), err
    assert not (tmp_path / "out" / "comparison.csv").exists()
    # numerics only, but the digest is not that of the recorded fields: refused
    (run / "config.yml").write_text(
        yaml.safe_dump(
            dict(
                cfg,
                scene_fields={
                    k: v
                    for k, v in cfg["scene_fields"].items()
                    if k not in changes or k in ("sub_steps", "resolution")
                },
            )
        )
    )
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err, err


def test_rollout_cli_refuses_a_model_of_another_scene_and_names_files_by_run(
    trained_run, tmp_path, capsys
):
    """`rolling-drive rollout --controller <run>/model.zip --scene X` refuses a model whose
    run was trained on other scene content (exit 2, one line); a copy of the scene under
    another name is the same scene.  Output files are named from the run folder: two runs'
    model.zip no longer write the same <scene>_model_seed0.csv."""
    import shutil

    from rolling_env.cli import main as cli_main

    scene, runs = trained_run
    model = runs / "myscene" / "ppo_seed0" / "model.zip"
    assert (
        cli_main(
            [
                "rollout",
                "--scene",
                "default",
                "--controller",
                str(model),
                "--out",
                str(tmp_path / "out"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("rolling-drive rollout: error:") and err.count("\n") == 1, err
    assert "content differs" in err and "mu" in err, err
    other = tmp_path / "runs" / "sac_seed0"
    shutil.copytree(model.parent, other)
    for m in (model, other / "model.zip"):
        assert (
            cli_main(
                [
                    "rollout",
                    "--scene",
                    "heavy_inf_friction",
                    "--controller",
                    str(m),
                    "--out",
                    str(tmp_path / "out"),
                    "--json",
                ]
            )
            == 0
        ), capsys.readouterr()
    names = sorted(p.name for p in (tmp_path / "out").glob("*.csv"))
    assert names == [
        "heavy_inf_friction_ppo_seed0-model_seed0.csv",
        "heavy_inf_friction_sac_seed0-model_seed0.csv",
    ], names


@pytest.mark.parametrize(
    "entry,name",
    [
        ({"n_epoch": 1, "learning_rte": 0.5}, "'learning_rte', 'n_epoch'"),
        ({"n_envs": 2.7}, "'n_envs' must be an integer"),
        ({"n_timesteps": 300.9}, "'n_timesteps' must be an integer"),
        ({"gamma": 1.5}, "'gamma' must be in (0, 1]"),
        ({"learning_rate": -1e-3}, "'learning_rate' must be in (0, inf)"),
        ({"learning_rate": "lin_x"}, "'learning_rate' must be a number or 'lin_<number>'"),
        ({"n_steps": "many"}, "'n_steps' must be an integer"),
        ({"use_sde": "yes"}, "'use_sde' must be true or false"),
        ({"policy_kwargs": "dict(activation_fn=os.system)"}, "'policy_kwargs'"),
        ({"policy_kwargs": "__import__('os').getcwd()"}, "'policy_kwargs'"),
        (
            {"policy_kwargs": "dict(net_arch=[64], nett=1)"},
            "'policy_kwargs': unknown key(s) ['nett']",
        ),
        (
            {"normalize": "{'norm_obs': True, 'clip_ob': 5}"},
            "'normalize': unknown key(s) ['clip_ob']",
        ),
        ({"noise_type": "normal", "noise_std": 0.1}, "PPO takes no action noise"),
        ({"seed": 1}, "'seed' cannot be set in the YAML"),
        ({"policy": "CnnPolicy"}, "'policy' must be 'MlpPolicy'"),
        (
            {"env_kwargs": {"scene": "default", "bogus": 1}},
            "'env_kwargs': unknown scene key 'bogus'",
        ),
    ],
)
def test_train_validates_every_hyperparameter(entry, name, tmp_path, capsys):
    """Unknown or misspelled keys were ignored, fractional n_envs / n_timesteps truncated,
    gamma 1.5 trained: each is one line, exit 2, naming the key, with no run folder."""
    from agents.train import main as train_main

    conf = tmp_path / "ppo.yml"
    conf.write_text(yaml.safe_dump({"default": {"n_envs": 1, "n_timesteps": 64, **entry}}))
    assert (
        train_main(
            [
                "--algo",
                "ppo",
                "--conf",
                str(conf),
                "--run-dir",
                str(tmp_path / "run"),
                "--no-progress",
            ]
        )
        == 2
    ), f"{entry} was accepted"
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and name in err, f"{entry}: {err}"
    assert not (tmp_path / "run").exists()


def test_td3_ornstein_uhlenbeck_noise_is_rejected_or_used(tmp_path, capsys):
    """noise_type ornstein-uhlenbeck trained TD3 with no noise at all: it is used now; an
    unknown noise type is refused naming noise_type."""
    from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise

    from agents.train import _setup, build_parser
    from agents.train import main as train_main

    conf = tmp_path / "td3.yml"
    entry = {
        "n_envs": 1,
        "n_timesteps": 64,
        "noise_type": "ornstein-uhlenbeck",
        "noise_std": 0.2,
        "target_policy_noise": 0.1,
        "learning_starts": 8,
        "replay_buffer_kwargs": "dict(handle_timeout_termination=True)",
    }
    conf.write_text(yaml.safe_dump({"default": entry}))
    args = build_parser().parse_args(
        ["--algo", "td3", "--conf", str(conf), "--run-dir", str(tmp_path / "run"), "--no-progress"]
    )
    model = _setup(args)[0]
    assert isinstance(model.action_noise, OrnsteinUhlenbeckActionNoise), model.action_noise
    assert np.allclose(model.action_noise._sigma, 0.2)
    assert model.target_policy_noise == 0.1 and model.learning_starts == 8
    conf.write_text(yaml.safe_dump({"default": dict(entry, noise_type="ou")}))
    assert (
        train_main(
            [
                "--algo",
                "td3",
                "--conf",
                str(conf),
                "--run-dir",
                str(tmp_path / "run2"),
                "--no-progress",
            ]
        )
        == 2
    )
    assert "'noise_type' must be one of" in capsys.readouterr().err


def test_rl_zoo_strings_and_sb3_keywords_reach_the_model(tmp_path):
    """Valid PPO keywords outside the old hard-coded list (target_kl, clip_range_vf,
    normalize_advantage, ...) were dropped silently; RL Zoo's lin_<x> schedules and
    nn.ReLU in policy_kwargs failed.  They all reach the model now."""
    import torch

    from agents.train import _setup, build_parser

    conf = tmp_path / "ppo.yml"
    conf.write_text(
        yaml.safe_dump(
            {
                "default": {
                    "n_envs": 1,
                    "n_timesteps": 64,
                    "n_steps": 32,
                    "batch_size": 32,
                    "target_kl": 0.02,
                    "clip_range_vf": 0.3,
                    "normalize_advantage": False,
                    "learning_rate": "lin_3e-4",
                    "clip_range": "lin_0.2",
                    "policy_kwargs": "dict(net_arch=[16], activation_fn=nn.ReLU)",
                }
            }
        )
    )
    args = build_parser().parse_args(
        ["--algo", "ppo", "--conf", str(conf), "--run-dir", str(tmp_path / "run"), "--no-progress"]
    )
    model = _setup(args)[0]
    assert model.target_kl == 0.02 and model.normalize_advantage is False
    assert model.clip_range_vf(1.0) == 0.3
    assert model.lr_schedule(0.5) == pytest.approx(1.5e-4), "lin_3e-4 at half-way"
    assert model.clip_range(0.25) == pytest.approx(0.05)
    assert model.policy.activation_fn is torch.nn.ReLU and model.policy.net_arch == [16]


def test_policy_kwargs_as_a_yaml_mapping_resolves_torch_names():
    """policy_kwargs written as a YAML mapping (not a string) passed 'nn.ReLU' on as a string,
    and SB3 failed later with an obscure traceback: the names resolve as in the string form,
    and an unknown one is refused naming the key."""
    import torch

    from agents.common import check_hyperparams

    hp = check_hyperparams(
        "sac",
        {
            "n_timesteps": 10,
            "policy_kwargs": {
                "net_arch": [64],
                "activation_fn": "nn.ReLU",
                "optimizer_class": "th.optim.AdamW",
            },
        },
    )
    kw = hp["kwargs"]["policy_kwargs"]
    assert kw["activation_fn"] is torch.nn.ReLU and kw["optimizer_class"] is torch.optim.AdamW, kw
    with pytest.raises(ValueError, match="policy_kwargs.*nn.NoSuchLayer"):
        check_hyperparams(
            "sac", {"n_timesteps": 10, "policy_kwargs": {"activation_fn": "nn.NoSuchLayer"}}
        )


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_a_loose_model_zip_is_loaded_with_its_own_algorithm(algo, tmp_path, capsys):
    """A model .zip without its run's config.yml was loaded as PPO (a loose SAC zip gave a
    traceback): the algorithm is read from the zip, and the missing VecNormalize statistics
    are warned about; the rollout CLI runs it."""
    import stable_baselines3 as sb3

    from agents.evaluate import model_algo
    from rolling_env.cli import main as cli_main
    from rolling_env.vector import RollingDriveVecEnv

    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]
    path = tmp_path / "loose" / f"{algo}_model.zip"
    path.parent.mkdir()
    cls(
        "MlpPolicy",
        RollingDriveVecEnv(1),
        device="cpu",
        **({"buffer_size": 100} if algo != "ppo" else {}),
    ).save(path)
    assert model_algo(path) == algo
    agent = load_agent(path, rolling_env.make("default"))
    assert type(agent.model) is cls, f"loaded as {type(agent.model).__name__}"
    assert f"has no {algo}_model_vecnormalize.pkl beside it" in capsys.readouterr().err
    assert (
        cli_main(
            [
                "rollout",
                "--scene",
                "default",
                "--controller",
                str(path),
                "--out",
                str(tmp_path / "out"),
                "--json",
            ]
        )
        == 0
    )
    assert (tmp_path / "out" / f"default_loose-{algo}_model_seed0.csv").exists()


def test_a_zip_that_is_no_sb3_model_is_one_line(tmp_path, capsys):
    import zipfile

    from agents.evaluate import model_algo
    from rolling_env.cli import main as cli_main

    junk = tmp_path / "junk.zip"
    junk.write_text("not a zip")
    assert cli_main(["rollout", "--controller", str(junk), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not a Stable-Baselines3 model zip" in err, err
    odd = tmp_path / "odd.zip"
    with zipfile.ZipFile(odd, "w") as z:
        z.writestr("data", json.dumps({"policy_class": {"__module__": "mypkg.policies"}}))
    with pytest.raises(ValueError, match="cannot tell which algorithm saved"):
        model_algo(odd)


def test_a_run_model_without_its_statistics_is_refused(trained_run, tmp_path):
    """A run that normalised observations (config.yml) but whose model lost its VecNormalize
    statistics would act on raw observations: refused, naming the missing file."""
    import shutil

    scene, runs = trained_run
    run = tmp_path / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    (run / "model_vecnormalize.pkl").unlink()
    with pytest.raises(
        ValueError,
        match="has no model_vecnormalize.pkl beside it, but its run normalised observations",
    ):
        load_agent(run / "model.zip", rolling_env.make(str(scene)))


def test_a_scene_that_cannot_be_built_is_one_line_naming_its_keys(tmp_path, capsys):
    """A scene that passes load_scene but needs more spring cells than the model allows
    (resolution 4096 over stroke_roll 0.9 m) crashed evaluate with a traceback: exit 2, one
    line naming the scene keys, nothing written; train says the same."""
    from agents.evaluate import main as evaluate_main
    from agents.train import main as train_main

    huge = _scene_file(tmp_path / "huge.yaml", resolution=4096, stroke_roll=0.9)
    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                str(huge),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "out"),
            ]
        )
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    last = err.strip().splitlines()[-1]
    assert "'resolution' = 4096" in last and "'stroke_roll' = 0.9" in last, err
    assert not (tmp_path / "out").exists()
    assert (
        train_main(["--algo", "ppo", "--scene", str(huge), "--run-dir", str(tmp_path / "run")]) == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'resolution' = 4096" in err, err


def test_evaluate_without_agents_refuses_unless_baselines_only(tmp_path, capsys):
    """A mistyped --runs (no such folder) or a scene with no trained agent there replaced the
    committed comparison with a baselines-only table, exit 0: now exit 2 naming --runs (and
    the scene) with nothing written; --baselines-only compares the two baselines alone."""
    from agents.evaluate import main as evaluate_main

    out = tmp_path / "out"
    base = ["--scenes", "heavy_inf_friction", "--episodes", "1", "--out", str(out)]
    with pytest.raises(SystemExit) as e:
        evaluate_main(base + ["--runs", str(tmp_path / "nonexistent")])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--runs: no folder" in err and "--baselines-only" in err, err
    (tmp_path / "runs" / "default" / "ppo_seed0").mkdir(parents=True)  # another scene's run
    with pytest.raises(SystemExit) as e:
        evaluate_main(base + ["--runs", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "no trained agent for scene 'heavy_inf_friction'" in err, err
    assert not out.exists() or not any(out.rglob("comparison*")), "a table was written"
    assert evaluate_main(base + ["--baselines-only", "--runs", str(tmp_path / "nonexistent")]) == 0
    with open(out / "comparison.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["controller"] for r in rows] == ["eq32-open-loop", "eq32-feedback"], rows


# ----------------------------------------------------------------- inputs (audit)
def test_evaluate_bounds_episodes(tmp_path, capsys, monkeypatch):
    """--episodes 1000000000 had no upper bound: the held-out targets were built until the
    process was killed for memory.  Now exit 2 at parse time naming --episodes and its range
    (1 to EPISODES_MAX), before any target is drawn or file written."""
    import agents.evaluate as ev

    def reached(*a, **k):
        raise AssertionError("the evaluation started with an unbounded --episodes")

    monkeypatch.setattr(ev, "held_out_targets", reached)
    for bad in ("1000000000", "100001", "0", "-3", "2.5"):
        with pytest.raises(SystemExit) as e:
            ev.main(
                [
                    "--baselines-only",
                    "--scenes",
                    "default",
                    "--episodes",
                    bad,
                    "--out",
                    str(tmp_path / "out"),
                ]
            )
        err = capsys.readouterr().err
        last = err.strip().splitlines()[-1]
        assert e.value.code == 2 and "--episodes" in last, f"{bad}: {err}"
        assert bad == "2.5" or "[1, 100000]" in last, f"{bad}: {err}"
    assert not (tmp_path / "out").exists()


def test_evaluate_refuses_duplicate_scenes(tmp_path, capsys):
    """--scenes default default evaluated the scene twice and wrote duplicate rows: refused
    naming --scenes, also where two spellings (name, path of the shipped file) have one key."""
    from agents.evaluate import main as evaluate_main

    shipped = str(rolling_env.scenes.SCENE_DIR / "default.yaml")
    for scenes in (["default", "default"], ["default", "heavy_inf_friction", shipped]):
        with pytest.raises(SystemExit) as e:
            evaluate_main(
                [
                    "--baselines-only",
                    "--scenes",
                    *scenes,
                    "--episodes",
                    "1",
                    "--out",
                    str(tmp_path / "out"),
                ]
            )
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert e.value.code == 2 and "--scenes:" in last and "same scene key 'default'" in last, (
            f"{scenes}: {last}"
        )
    assert not (tmp_path / "out").exists()


def test_evaluate_refuses_a_run_named_like_a_baseline(trained_run, tmp_path, capsys):
    """A run folder named eq32-feedback replaced the baseline's row silently."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    shutil.copytree(runs / "myscene" / "ppo_seed0", tmp_path / "runs" / "myscene" / "eq32-feedback")
    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                str(scene),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "out"),
            ]
        )
    err = capsys.readouterr().err
    assert e.value.code == 2 and "has the name of a baseline" in err, err


def _damage(run: Path, kind: str) -> str:
    """Damage one file of a copied run folder; returns the name of the damaged file."""
    import zipfile

    cfg = run / "config.yml"
    if kind == "yaml":
        cfg.write_text("scene: [\n")
    elif kind == "list":
        cfg.write_text("- 1\n- 2\n")
    elif kind == "env_kwargs":
        cfg.write_text(yaml.safe_dump(dict(yaml.safe_load(cfg.read_text()), env_kwargs=[1, 2])))
    elif kind == "utf8":
        cfg.write_bytes(b"scene: \xff\xfe\n")
    elif kind == "pkl":
        stats = run / "model_vecnormalize.pkl"
        stats.write_bytes(stats.read_bytes()[: len(stats.read_bytes()) // 2])
        return stats.name
    elif kind == "pth":
        good = run / "model.zip"
        bad = run / "bad.zip"
        with zipfile.ZipFile(good) as zi, zipfile.ZipFile(bad, "w") as zo:
            for item in zi.infolist():
                data = zi.read(item.filename)
                zo.writestr(item, data[: len(data) // 2] if item.filename == "policy.pth" else data)
        bad.replace(good)
        return good.name
    elif kind == "meta":
        (run / "meta.json").write_text('{"env_steps": 64, "wall')
        return "meta.json"
    elif kind == "npz":
        ev = run / "evaluations.npz"
        ev.write_bytes(ev.read_bytes()[:100])
        return ev.name
    return cfg.name


@pytest.mark.parametrize(
    "kind", ["yaml", "list", "env_kwargs", "utf8", "pkl", "pth", "meta", "npz"]
)
def test_damaged_run_files_are_one_line_naming_the_file(trained_run, tmp_path, capsys, kind):
    """A config.yml that is invalid YAML, a list, has env_kwargs [1, 2] or is not UTF-8, a
    truncated model_vecnormalize.pkl, a model.zip with a damaged policy.pth (and, for
    evaluate, a damaged meta.json or evaluations.npz) gave raw tracebacks, exit 1: now one
    line naming the file, exit 2, in `rolling-drive rollout` and `agents.evaluate`, with
    nothing written."""
    import shutil

    from agents.evaluate import main as evaluate_main
    from rolling_env.cli import main as cli_main

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    for f in run.glob("best_model*"):  # model.zip is the file used
        f.unlink()
    name = _damage(run, kind)
    out = tmp_path / "out"
    if kind not in ("meta", "npz"):  # the rollout reads neither
        code = cli_main(
            [
                "rollout",
                "--scene",
                str(scene),
                "--controller",
                str(run / "model.zip"),
                "--out",
                str(out),
            ]
        )
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, f"{kind}: exit {code}: {err}"
        assert err.startswith("rolling-drive rollout: error:") and name in err, f"{kind}: {err}"
    with pytest.raises(SystemExit) as e:
        evaluate_main(
            [
                "--scenes",
                str(scene),
                "--runs",
                str(tmp_path / "runs"),
                "--episodes",
                "1",
                "--out",
                str(out),
            ]
        )
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert e.value.code == 2 and name in last and "Traceback" not in last, f"{kind}: {last}"
    assert not [p for p in out.rglob("*") if p.is_file()], f"{kind}: files written"


@pytest.mark.parametrize(
    "algo,policy_kwargs,name",
    [
        ("ppo", "dict(net_arch=[-5])", "net_arch must be a list"),
        ("ppo", "dict(net_arch=[100000, 100000])", "each an integer in [1, 1024]"),
        ("ppo", "dict(net_arch=[0])", "net_arch must be a list"),
        ("ppo", "dict(net_arch=[8, 8, 8, 8, 8, 8, 8, 8, 8])", "at most 8 hidden-layer widths"),
        ("ppo", "dict(net_arch=dict(pi=[64], qf=[64]))", "takes the keys pi and vf"),
        ("sac", "dict(net_arch=dict(pi=[64], vf=[64]))", "takes the keys pi and qf"),
        ("ppo", "dict(log_std_init=1e308)", "log_std_init must be in [-20, 2]"),
        ("ppo", "dict(activation_fn=nn.Dropout)", "activation_fn must be a torch.nn activation"),
        ("ppo", "dict(activation_fn=nn.GLU)", "activation_fn must be a torch.nn activation"),
        ("ppo", "dict(activation_fn=th.optim.Adam)", "activation_fn must be a torch.nn activation"),
        ("ppo", "dict(ortho_init=2)", "ortho_init must be true or false"),
        ("sac", "dict(n_critics=0)", "n_critics must be an integer in [1, 10]"),
        ("td3", "dict(optimizer_class=nn.ReLU)", "optimizer_class must be a torch.optim"),
        (
            "ppo",
            "dict(optimizer_kwargs=dict(weight_decay=-1))",
            "ActorCriticPolicy cannot be built with",
        ),
        ("sac", "dict(optimizer_kwargs=dict(bogus=1))", "SACPolicy cannot be built with"),
    ],
)
def test_train_validates_policy_kwargs_values(algo, policy_kwargs, name, tmp_path, capsys):
    """Bad values inside policy_kwargs reached torch: a negative width (RuntimeError), a huge
    allocation, NaN in the first update from log_std_init 1e308 (exit 1, a run folder with
    no model); net_arch [0], nn.Dropout and ortho_init 2 were accepted.  Now one line naming
    policy_kwargs, exit 2, no run folder; what only building the policy finds (an optimizer
    keyword) too."""
    from agents.train import main as train_main

    conf = tmp_path / f"{algo}.yml"
    entry = {"n_envs": 1, "n_timesteps": 64, "policy_kwargs": policy_kwargs}
    if algo != "ppo":
        entry.update(buffer_size=100, learning_starts=8)
    conf.write_text(yaml.safe_dump({"default": entry}))
    assert (
        train_main(
            [
                "--algo",
                algo,
                "--conf",
                str(conf),
                "--run-dir",
                str(tmp_path / "run"),
                "--no-progress",
            ]
        )
        == 2
    ), f"{policy_kwargs} was accepted"
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "hyper-parameter 'policy_kwargs'" in err and name in err, err
    assert not (tmp_path / "run").exists()


def test_shipped_policy_kwargs_and_valid_ones_pass():
    """The shipped configs, and valid values of every kind the check knows, pass unchanged."""
    import torch

    from agents.common import check_hyperparams

    for algo in ("ppo", "sac", "td3"):
        for key in ("RollingDrive-v0", *rolling_env.list_scenes()):
            check_hyperparams(algo, load_hyperparams(algo, key))
    pk = check_hyperparams(
        "sac",
        {
            "n_timesteps": 8,
            "policy_kwargs": (
                f"dict(net_arch=dict(pi={[1024] * 8}, qf=[]), activation_fn=nn.SiLU, "
                f"log_std_init=-20, "
                "n_critics=10, clip_mean=1.5, use_expln=True, optimizer_class=th.optim.AdamW, "
                "optimizer_kwargs=dict(weight_decay=0.01))"
            ),
        },
    )["kwargs"]["policy_kwargs"]
    assert pk["activation_fn"] is torch.nn.SiLU and pk["net_arch"]["pi"] == [1024] * 8, pk


def test_exponent_numbers_in_hyperparameter_yaml(tmp_path):
    """PyYAML (YAML 1.1) reads 3e-4, 9e-1 and 1e3 as strings: they were refused as 'must be a
    number, got '3e-4''.  The project's YAML loader (``rolling_env.scenes.read_yaml``, also
    for scene files and run configs) reads them as floats, as YAML 1.2 does; n_timesteps 1e3
    is the integer 1000, 1.5e0 for an integer is still refused, and lin_2e-1 stays a string
    (a schedule)."""
    from agents.common import check_hyperparams
    from agents.train import _setup, build_parser

    conf = tmp_path / "ppo.yml"
    conf.write_text(
        "default:\n  n_timesteps: 1e3\n  n_envs: 1\n  learning_rate: 3e-4\n"
        "  gamma: 9e-1\n  n_steps: 6.4e+1\n  batch_size: 32\n  ent_coef: 1e-3\n"
        "  clip_range: lin_2e-1\n  policy_kwargs: {net_arch: [8], log_std_init: -1e0}\n"
        "  normalize: {norm_obs: true, clip_obs: 1e1}\n"
    )
    assert yaml.safe_load("x: 3e-4")["x"] == "3e-4", "PyYAML's reading changed: the test is moot"
    hp = load_hyperparams("ppo", "default", conf)
    checked = check_hyperparams("ppo", hp)
    kw = checked["kwargs"]
    assert checked["n_timesteps"] == 1000 and type(checked["n_timesteps"]) is int, checked
    assert kw["learning_rate"] == 3e-4 and kw["gamma"] == 0.9 and kw["n_steps"] == 64, kw
    assert kw["ent_coef"] == 1e-3 and kw["policy_kwargs"]["log_std_init"] == -1.0, kw
    assert checked["normalize"]["clip_obs"] == 10.0, checked["normalize"]
    args = build_parser().parse_args(
        ["--algo", "ppo", "--conf", str(conf), "--run-dir", str(tmp_path / "run"), "--no-progress"]
    )
    model = _setup(args)[0]
    assert model.learning_rate == 3e-4 and model.gamma == 0.9 and model.n_steps == 64
    for key, value, msg in (
        ("n_timesteps", "1.5e0", "'n_timesteps' must be an integer"),
        ("gamma", "2e0", "'gamma' must be in (0, 1]"),
    ):
        entry = {"n_timesteps": "8", key: value}  # n_timesteps given once
        conf.write_text("default:\n" + "".join(f"  {k}: {v}\n" for k, v in entry.items()))
        with pytest.raises(ValueError) as e:
            check_hyperparams("ppo", load_hyperparams("ppo", "default", conf))
        assert msg in str(e.value), str(e.value)


def _overwrite_argv(run):
    return [
        "--algo",
        "ppo",
        "--n-timesteps",
        "64",
        "--n-envs",
        "1",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "1",
        "--no-progress",
        "--run-dir",
        str(run),
    ]


def test_overwrite_keeps_the_earlier_run_when_the_new_one_fails(tmp_path, monkeypatch, capsys):
    """--overwrite deleted the earlier run before learning: a rerun that failed while
    learning destroyed the good model.  The new run trains in <run>.overwrite and replaces
    the earlier one only once finished; a failed one leaves the earlier run as it was (and
    its own files in <run>.overwrite, which a further --overwrite refuses to clobber)."""
    import shutil

    import stable_baselines3 as sb3

    from agents.train import main as train_main
    from agents.train import staging_folder

    run = tmp_path / "run"
    assert train_main(_overwrite_argv(run)) == 0
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    learn = sb3.PPO.learn

    def boom(self, *a, **k):
        raise RuntimeError("raised inside learn")

    monkeypatch.setattr(sb3.PPO, "learn", boom)
    with pytest.raises(RuntimeError, match="raised inside learn"):
        train_main(_overwrite_argv(run) + ["--overwrite"])
    after = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    assert after == before, "the earlier run was changed by a failed --overwrite"
    staging = staging_folder(run)
    assert staging == tmp_path / "run.overwrite" and (staging / "config.yml").exists()
    assert "the earlier run in" in capsys.readouterr().err
    monkeypatch.setattr(sb3.PPO, "learn", learn)
    assert train_main(_overwrite_argv(run) + ["--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "run.overwrite" in err and "nothing was deleted" in err, err
    shutil.rmtree(staging)
    assert train_main(_overwrite_argv(run) + ["--overwrite"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"], "staging or old run left"
    assert (run / "model.zip").read_bytes() != before["model.zip"], "not replaced"
    load_agent(run / "model.zip", rolling_env.make("default"))


def test_overwrite_stopped_by_sigterm_keeps_both_runs(tmp_path):
    """SIGTERM during an --overwrite run: exit 143, the earlier run untouched, and the new
    run's loadable checkpoint in <run>.overwrite (where the message says it is)."""
    from agents.train import main as train_main

    run = tmp_path / "run"
    assert train_main(_overwrite_argv(run)) == 0
    before = (run / "model.zip").read_bytes()
    proc = subprocess.Popen(
        _train(tmp_path, "--overwrite", timesteps=10**7),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    staging = tmp_path / "run.overwrite"
    deadline = time.time() + 120
    while not (staging / "evaluations.npz").exists() and time.time() < deadline:
        time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    assert str(staging) in err and "is kept" in err, err[-2000:]
    assert (run / "model.zip").read_bytes() == before, "the earlier run was changed"
    assert not json.loads((run / "meta.json").read_text())["interrupted"]
    assert json.loads((staging / "meta.json").read_text())["interrupted"]
    env = rolling_env.make("default")
    agent = load_agent(staging / "checkpoint.zip", env)
    a, _ = agent.predict(env.reset(seed=0)[0])
    assert env.action_space.contains(np.asarray(a, np.float32))


def test_scene_runs_skips_hidden_and_overwrite_folders(tmp_path):
    """The run folders of a scene are its visible subfolders: a hidden one (an earlier run
    that ``--overwrite`` could not delete) and ``<run>.overwrite`` (a replacement that failed
    or was stopped) were evaluated as extra controllers."""
    from agents.evaluate import scene_runs

    base = tmp_path / "runs" / "default"
    for name in ("ppo_seed0", "sac_seed0", ".ppo_seed0.replaced-123", "ppo_seed0.overwrite"):
        (base / name).mkdir(parents=True)
    (base / "notes.txt").write_text("not a run")
    got = [p.name for p in scene_runs("default", tmp_path / "runs")]
    assert got == ["ppo_seed0", "sac_seed0"], got


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_training_is_reproducible_from_the_seed(algo, tmp_path):
    """Issue #4: everything reproducible from --seed.  Two runs with the same seed give
    bit-identical policy parameters, VecNormalize statistics and evaluation log; another seed
    gives other parameters (so the check can fail).  Both in this process (torch on one
    thread, as agents.train sets it)."""
    import torch

    from agents.train import main as train_main

    conf = tmp_path / f"{algo}.yml"
    entry = {
        "n_envs": 2,
        "n_timesteps": 256,
        "normalize": "{'norm_obs': True}",
        "policy_kwargs": "dict(net_arch=[16])",
    }
    entry.update(
        {"n_steps": 64, "batch_size": 32, "n_epochs": 2}
        if algo == "ppo"
        else {"buffer_size": 512, "learning_starts": 32, "batch_size": 16}
    )
    conf.write_text(yaml.safe_dump({"default": entry}))

    def train(seed, name):
        run = tmp_path / name
        assert (
            train_main(
                [
                    "--algo",
                    algo,
                    "--conf",
                    str(conf),
                    "--seed",
                    str(seed),
                    "--run-dir",
                    str(run),
                    "--eval-freq",
                    "128",
                    "--eval-episodes",
                    "1",
                    "--no-progress",
                ]
            )
            == 0
        )
        agent = load_agent(run / "model.zip", rolling_env.make("default"))
        params = {k: v.clone() for k, v in agent.model.policy.state_dict().items()}
        with np.load(run / "evaluations.npz") as d:
            evals = d["results"].copy()
        return params, agent.vecnorm.obs_rms.mean.copy(), evals

    p1, m1, e1 = train(5, "a")
    p2, m2, e2 = train(5, "b")
    p3, _, _ = train(6, "c")
    assert p1.keys() == p2.keys()
    for k in p1:
        assert torch.equal(p1[k], p2[k]), f"{algo}: {k} differs between two runs with seed 5"
    assert np.array_equal(m1, m2) and np.array_equal(e1, e2), (
        f"{algo}: VecNormalize statistics or evaluation log differ between two runs with seed 5"
    )
    assert any(not torch.equal(p1[k], p3[k]) for k in p1), (
        f"{algo}: seeds 5 and 6 gave the same parameters: the seed is not used"
    )
