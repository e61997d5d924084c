"""Period-level agents: one Eq. 32 working point per excitation period, played tick by tick."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

import rolling_env
from agents.hyperparams import check_hyperparams
from agents.period import HOLD, PeriodAgent, PeriodExcitation, PeriodVecEnv
from rolling_env.env.baselines import Eq32Design
from rolling_env.env.rollout import rollout
from rolling_env.env.scenes import load_scene


@pytest.mark.parametrize("scene", ["default", "light_stiff", "heavy_inf_friction"])
@pytest.mark.parametrize("direction", [1, -1])
def test_an_eq32_working_point_plays_the_designs_ticks(scene, direction):
    """``encode`` of a design's (delta, creep, w) executes ``Eq32Design.action`` tick by tick
    (to float32 rounding of the round trip through the action box)."""
    sc = load_scene(scene)
    design, ex = Eq32Design(sc), PeriodExcitation(sc)
    delta, creep = design.choose(0.5 * design.v_max)
    point = ex.decode(ex.encode(delta, creep, design.w, direction))
    assert not point["hold"] and point["direction"] == direction
    for j in range(ex.ticks):
        np.testing.assert_allclose(
            ex.tick(j, point, False),
            design.action(j, delta, creep, direction),
            rtol=0,
            atol=2e-7,
            err_msg=f"{scene}: tick {j} of the period differs from the Eq. 32 design's",
        )


def test_the_action_box_spans_the_design_space():
    sc = load_scene("default")
    ex = PeriodExcitation(sc)
    d = ex.design
    lo, hi = ex.decode([-1, -1, -1, -1]), ex.decode([1, 1, 1, 1])
    assert (lo["direction"], hi["direction"]) == (-1, 1)
    assert lo["delta"] == pytest.approx(d.delta_min) and hi["delta"] == pytest.approx(d.delta_min)
    assert (lo["creep"], hi["creep"]) == (0.0, pytest.approx(d.creep_cap))
    assert (lo["w"], hi["w"]) == (2.0, pytest.approx(ex.w_max))
    assert (lo["N1"], hi["N1"]) == (pytest.approx(sc.N_min), pytest.approx(sc.N_max))
    assert ex.decode([0.9 * HOLD, 0, 0, 0])["hold"] and not ex.decode([HOLD, 0, 0, 0])["hold"]
    assert ex.decode([5, -5, 5, -5]) == ex.decode([1, -1, 1, -1]), "actions are clipped to the box"


def test_a_hold_releases_once_then_keeps_the_runner_stuck():
    sc = load_scene("default")
    ex = PeriodExcitation(sc)
    hold = ex.decode([0, 0, 0, 0])
    first = [ex.tick(j, hold, False) for j in range(ex.ticks)]
    again = [ex.tick(j, hold, True) for j in range(ex.ticks)]
    np.testing.assert_array_equal(first[0], [-1, 0, 0], err_msg="entering a hold releases")
    for a in first[1:] + again:
        np.testing.assert_array_equal(a, [1, 0, 0], err_msg="a hold is N_max, no rates")


def _plain_period(env, actions):
    """Step a plain env through ticks; return (summed reward, summed slip work, last obs)."""
    rew = slip = 0.0
    for a in actions:
        obs, r, _, _, info = env.step(a)
        rew += r
        slip += info["slip_work"]
    return rew, slip, obs


def test_a_wrapper_step_is_one_period_of_the_env_with_summed_reward_and_slip():
    sc = load_scene("default")
    ex = PeriodExcitation(sc)
    venv = PeriodVecEnv(DummyVecEnv([lambda: rolling_env.make("default")]))
    venv.seed(3)
    venv.reset()
    plain = rolling_env.make("default")
    plain.reset(seed=3)
    rng = np.random.default_rng(0)
    holding = False
    for _ in range(5):
        a = rng.uniform(-1, 1, 4).astype(np.float32)  # as the policy gives it
        obs, rew, done, infos = venv.step(a[None, :])
        point = ex.decode(a)
        r, w, o = _plain_period(plain, [ex.tick(j, point, holding) for j in range(ex.ticks)])
        holding = point["hold"]
        np.testing.assert_array_equal(obs[0], o, err_msg="the observation after the period")
        assert rew[0] == pytest.approx(r, rel=1e-6), "the period's reward is the ticks' sum"
        assert infos[0]["slip_work"] == pytest.approx(w, rel=1e-12, abs=0.0), "summed slip"


def test_an_episode_is_64_decisions_and_ends_on_a_periods_last_tick():
    venv = PeriodVecEnv(DummyVecEnv([lambda: rolling_env.make("default")]))
    venv.reset()
    steps = 0
    done = np.array([False])
    while not done[0]:
        _, _, done, infos = venv.step(np.array([[0.5, 0.0, 0.0, 1.0]], np.float32))
        steps += 1
    assert steps == 512 // 8, f"{steps} decisions in a 512-tick episode of 8-tick periods"
    assert "terminal_observation" in infos[0]


class _Fixed:
    """A policy that returns the same period action for every observation it is given."""

    def __init__(self, action):
        self.action = np.asarray(action, np.float32)
        self.calls = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        self.calls += 1
        return np.tile(self.action, (len(obs), 1)), state


def test_the_agent_plays_what_the_training_wrapper_plays():
    action = [0.8, 0.3, -0.2, 0.9]
    env = rolling_env.make("default")
    policy = _Fixed(action)
    data = rollout(env, PeriodAgent(policy, env), seed=1)
    assert policy.calls == 64, f"the policy decided {policy.calls} times in 512 ticks"
    venv = PeriodVecEnv(DummyVecEnv([lambda: rolling_env.make("default")]))
    venv.seed(1)
    venv.reset()
    for _ in range(64):
        obs, _, done, infos = venv.step(np.array([action], np.float32))
    assert done[0]
    assert data["xstar"][-1] == pytest.approx(infos[0]["xstar"], rel=1e-12, abs=0.0)


def test_bad_period_settings_are_one_line():
    with pytest.raises(ValueError, match="period_actions must be true or false"):
        check_hyperparams("ppo", {"n_timesteps": 64, "period_actions": "yes"})
    with pytest.raises(ValueError, match="'period_actions' and 'residual' exclude each other"):
        check_hyperparams(
            "ppo", {"n_timesteps": 64, "period_actions": True, "residual": "eq32-feedback"}
        )
    with pytest.raises(ValueError, match=r"episode_steps = 100 is no multiple of the 8 ticks"):
        PeriodExcitation(load_scene("default", episode_steps=100))


def test_a_short_period_run_trains_saves_and_evaluates(tmp_path):
    from agents.loading import load_agent
    from agents.train import main as train_main

    run = tmp_path / "run"
    args = ["--algo", "ppo", "--scene", "default", "--period-actions", "--n-timesteps", "64"]
    args += ["--n-envs", "1", "--eval-freq", "64", "--eval-episodes", "1", "--no-progress"]
    assert train_main(args + ["--run-dir", str(run)]) == 0
    env = rolling_env.make("default")
    agent = load_agent(run / "model.zip", env)
    assert isinstance(agent, PeriodAgent), f"loaded as {type(agent).__name__}"
    data = rollout(env, agent, seed=0)
    assert len(data["xstar"]) == 512 and np.isfinite(data["xstar"]).all()
    cfg = run / "config.yml"
    cfg.write_text(cfg.read_text().replace("period_actions: true", "period_actions: 'yes'"))
    with pytest.raises(ValueError, match=r"config\.yml: period_actions must be true or false"):
        load_agent(run / "model.zip", env)


def test_holds_play_alike_in_training_and_evaluation():
    """A period sequence with holds (entered, kept, left, in two stretches) gives the same
    episode through ``PeriodAgent`` on a single env as through ``PeriodVecEnv``."""
    sc = load_scene("default")
    ex = PeriodExcitation(sc)
    d = Eq32Design(sc)
    drive = ex.encode(*d.choose(0.6 * d.v_max), d.w)
    hold = np.zeros(4)
    seq = [hold if k in (3, 4, 5, 10, 20, 21) else drive for k in range(64)]

    class Seq:
        k = 0

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            a = np.tile(seq[self.k], (len(obs), 1)).astype(np.float32)
            self.k += 1
            return a, state

    env = rolling_env.make("default")
    data = rollout(env, PeriodAgent(Seq(), env), seed=2)
    venv = PeriodVecEnv(DummyVecEnv([lambda: rolling_env.make("default")]))
    venv.seed(2)
    venv.reset()
    slip = 0.0
    for a in seq:
        _, _, done, infos = venv.step(np.asarray([a], np.float32))
        slip += infos[0]["slip_work"]
    assert done[0]
    assert data["xstar"][-1] == infos[0]["xstar"], "the holds played differently"
    assert data["total_slip_work"] == pytest.approx(slip, rel=1e-12), "the episodes' slip work"


def test_a_td3_period_run_sizes_its_action_noise_to_the_period_action(tmp_path):
    """TD3's action noise (td3.yml: normal) has the period action's four numbers."""
    from agents.train import main as train_main

    args = ["--algo", "td3", "--scene", "default", "--period-actions", "--n-timesteps", "16"]
    args += ["--n-envs", "1", "--eval-freq", "16", "--eval-episodes", "1", "--no-progress"]
    assert train_main(args + ["--run-dir", str(tmp_path / "run")]) == 0
