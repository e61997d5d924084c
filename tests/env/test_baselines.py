"""The Eq. 32 baseline controllers on the env: exact where Eq. 32 is, feedback at least as good
as open loop, one env or a batch, and the design's inversion of Eq. 32."""

from __future__ import annotations

import numpy as np
import pytest

import rolling_env
from agents.baselines import Eq32Design, Eq32Feedback, Eq32OpenLoop
from agents.evaluate import held_out_targets
from rolling_env.env.rollout import rollout


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
    from rolling_env.env.sb3_vec import RollingDriveVecEnv

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
