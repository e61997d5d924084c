"""Residual agents: a policy's action added to an Eq. 32 baseline's (agents.residual)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import rolling_env
from agents.baselines import Eq32Feedback, Eq32OpenLoop
from agents.loading import load_agent
from agents.residual import BASES, ResidualAgent, ResidualVecEnv, augment, check_residual, combine
from rolling_env.env.rollout import rollout
from tests.train_argv import tiny_ppo_argv


def _actions(data):
    return np.stack([data["a_force"], data["a_roll"], data["a_creep"]], axis=1)


class _Const:
    """A policy stub: the same action for every observation (records what it saw)."""

    def __init__(self, value):
        self.value = np.asarray(value, np.float32)
        self.seen = []

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs)
        self.seen.append(obs.copy())
        shape = obs.shape[:-1] + (3,)
        return np.broadcast_to(self.value, shape).copy(), state


def test_combine_adds_the_scaled_policy_and_clips_to_the_action_box():
    base = np.array([[0.5, -0.9, 0.0]], np.float32)
    assert np.array_equal(combine(base, np.zeros((1, 3)), 0.25), base), "zero policy: base"
    got = combine(base, np.array([[1.0, -1.0, 4.0]]), 0.25)  # policy clipped to 1 first
    assert np.allclose(got, [[0.75, -1.0, 0.25]], atol=1e-7), got
    assert combine(base, np.array([[1.0, 1.0, 1.0]]), 2.0).max() <= 1.0


@pytest.mark.parametrize(
    "base,scale,name",
    [
        ("pid", 0.25, "residual"),
        ("eq32-feedback", 0.0, "residual_scale"),
        ("eq32-feedback", 3.0, "residual_scale"),
        ("eq32-feedback", True, "residual_scale"),
    ],
)
def test_bad_residual_settings_name_the_parameter(base, scale, name):
    with pytest.raises(ValueError, match=name):
        check_residual(base, scale)


@pytest.mark.parametrize("base", sorted(BASES))
def test_a_zero_policy_is_its_baseline(base):
    """With the policy at zero the residual agent takes the baseline's actions tick by tick,
    so the episode is the baseline's to the bit; the policy sees the env's 13 numbers and
    then the baseline's action."""
    env = rolling_env.make("default")
    policy = _Const([0.0, 0.0, 0.0])
    agent = ResidualAgent(policy, base, 0.25, env)
    got = rollout(env, agent, seed=0, target=3e-7)
    ref = rollout(env, BASES[base].from_env(env), seed=0, target=3e-7)
    assert np.array_equal(_actions(got), _actions(ref)), f"{base}: actions differ"
    assert got["final_error"] == ref["final_error"]
    seen = np.concatenate([s.reshape(-1, 16) for s in policy.seen])
    assert np.array_equal(seen[:, 13:], _actions(ref)[: len(seen)]), (
        "the policy's observation ends with the baseline's action of the same tick"
    )


def test_a_constant_residual_moves_the_actions_by_scale_times_it():
    env = rolling_env.make("default")
    agent = ResidualAgent(_Const([0.2, 0.0, -0.4]), "eq32-open-loop", 0.5, env)
    got = rollout(env, agent, seed=1, target=2e-7)
    ref = rollout(env, Eq32OpenLoop.from_env(env), seed=1, target=2e-7)
    # the open-loop plan does not depend on what the runner does, so only the offset differs
    want = np.clip(_actions(ref) + np.array([0.1, 0.0, -0.2]), -1, 1)
    assert np.allclose(_actions(got), want, atol=1e-6), np.abs(_actions(got) - want).max()


def test_residual_vec_env_with_zero_actions_runs_the_baseline_across_episode_ends():
    """The training wrapper: zero residuals drive each env as the baseline does, through the
    same-step autoreset; a finished env's terminal observation carries the baseline's action
    too (16 numbers), and the baseline restarts its plan on the new episode."""
    from rolling_env.env.sb3_vec import RollingDriveVecEnv

    steps = 600  # one episode end (512 ticks)
    venv = ResidualVecEnv(
        RollingDriveVecEnv(2, scene="default", episode_steps=256), "eq32-feedback", 0.25
    )
    venv.seed(5)
    ref_env = RollingDriveVecEnv(2, scene="default", episode_steps=256)
    ref_env.seed(5)
    assert venv.observation_space.shape == (16,)
    obs, ref_obs = venv.reset(), ref_env.reset()
    ctrl = Eq32Feedback.from_env(ref_env)
    starts = np.ones(2, bool)
    ends = 0
    for _ in range(steps):
        act, _ = ctrl.predict(ref_obs, episode_start=starts)
        assert np.array_equal(obs[:, 13:], act), "observation ends with the baseline's action"
        obs, rew, done, infos = venv.step(np.zeros((2, 3), np.float32))
        ref_obs, ref_rew, starts, ref_infos = ref_env.step(act)
        assert np.array_equal(obs[:, :13], ref_obs) and np.array_equal(rew, ref_rew)
        for i in np.flatnonzero(done):
            ends += 1
            term = infos[i]["terminal_observation"]
            assert term.shape == (16,)
            assert np.array_equal(term[:13], ref_infos[i]["terminal_observation"])
    assert ends == 4, f"{ends} episode ends in {steps} steps of 2 envs with 256-tick episodes"


def test_residual_hyperparameters_are_checked(tmp_path, capsys):
    from agents.train import main as train_main

    conf = tmp_path / "hp.yml"
    conf.write_text(
        yaml.safe_dump(
            {
                "RollingDrive-v0": {
                    "n_timesteps": 64,
                    "n_envs": 1,
                    "n_steps": 64,
                    "batch_size": 64,
                    "residual_scale": 0.5,
                }
            }
        )
    )
    rc = train_main(
        ["--algo", "ppo", "--conf", str(conf), "--no-progress", "--run-dir", str(tmp_path / "run")]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "residual_scale" in err and "needs 'residual'" in err, err
    assert not (tmp_path / "run").exists()
    rc = train_main(
        [
            "--algo",
            "ppo",
            "--conf",
            str(conf),
            "--no-progress",
            "--residual",
            "eq32-feedback",
            "--residual-scale",
            "5",
            "--run-dir",
            str(tmp_path / "run"),
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "residual_scale must be a number in (0, 2]" in err, err


def test_a_trained_residual_run_loads_as_a_residual_agent(tmp_path, monkeypatch):
    """agents.train --residual: the run folder is named <algo>-residual_seed<N>, its config
    names the baseline, and load_agent gives back an agent that acts through it."""
    from agents.train import main as train_main

    monkeypatch.chdir(tmp_path)
    assert (
        train_main(
            tiny_ppo_argv(
                *("--scene", "default", "--seed", "2", "--residual", "eq32-feedback"),
                *("--residual-scale", "0.1"),
                timesteps=256,
                n_envs=2,
            )
        )
        == 0
    )
    run = tmp_path / "runs" / "default" / "ppo-residual_seed2"
    cfg = yaml.safe_load((run / "config.yml").read_text())
    assert cfg["residual"] == "eq32-feedback" and cfg["residual_scale"] == 0.1
    env = rolling_env.make("default")
    agent = load_agent(run / "model.zip", env)
    assert isinstance(agent, ResidualAgent) and agent.scale == 0.1
    data = rollout(env, agent, seed=0, target=2e-7)
    base = rollout(env, Eq32Feedback.from_env(env), seed=0, target=2e-7)
    # a barely trained policy keeps every action within scale of the baseline's first tick
    assert np.all(np.abs(_actions(data)[0] - _actions(base)[0]) <= 0.1 + 1e-6)
    assert np.isfinite(data["final_error"])
    # without its config.yml a residual model cannot be told from a plain one: refused, named
    import shutil

    alone = tmp_path / "alone"
    alone.mkdir()
    for f in ("model.zip", "model_vecnormalize.pkl"):
        shutil.copy(run / f, alone / f)
    with pytest.raises(ValueError, match="it is a residual agent"):
        load_agent(alone / "model.zip", env)


def test_augment_keeps_the_env_observation_first():
    obs = np.arange(13, dtype=np.float32)
    out = augment(obs, [1, 2, 3])
    assert out.dtype == np.float32 and np.array_equal(out, np.r_[obs, 1, 2, 3])
