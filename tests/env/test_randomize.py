"""Scenes that draw their physics per episode (scene key ``randomize``)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import rolling_env
from rolling_env.env.scenes import SCENE_DIR, load_scene

FAMILY = str(SCENE_DIR / "families" / "default-randomized.yaml")


def test_draws_lie_in_their_ranges_and_follow_their_laws():
    """mu and the mass are drawn log-uniformly (their log's mean is the log-midpoint), the
    load uniformly (its mean is the midpoint); 400 draws: the means to +-4 standard errors."""
    env = rolling_env.make(FAMILY)
    sc = env.unwrapped.scene
    ranges = {k: (lo, hi) for k, lo, hi in sc.randomize}
    draws = {k: [] for k in ranges}
    for s in range(400):
        _, info = env.reset(seed=s)
        for k, x in info["scene_draw"].items():
            lo, hi = ranges[k]
            assert lo <= x <= hi, (k, x)
            draws[k].append(x)
    n = 400
    for k in ("mu", "runner_mass"):
        lo, hi = ranges[k]
        logs = np.log(draws[k])
        se = (math.log(hi) - math.log(lo)) / math.sqrt(12 * n)
        assert abs(logs.mean() - 0.5 * (math.log(lo) + math.log(hi))) < 4 * se, k
    lo, hi = ranges["F_ext"]
    assert abs(np.mean(draws["F_ext"]) - 0.5 * (lo + hi)) < 4 * (hi - lo) / math.sqrt(12 * n)


def test_an_episode_runs_the_drawn_physics():
    """The randomised env's episode is, tick by tick, the episode of the plain scene with the
    drawn values (same target, same actions): runner position and velocity, forces and slip
    work to the bit.  Only the tangential-force observation's scale and the wear reward's
    reference stay the nominal scene's (mu N_max), so that they mean the same in every
    episode."""
    env = rolling_env.make(FAMILY)
    nominal = env.unwrapped.scene
    _, info = env.reset(seed=7)
    draw = info["scene_draw"]
    plain = rolling_env.make("default", **draw)
    plain.reset(seed=0, options={"target": info["target"]})
    rng = np.random.default_rng(7)
    for k in range(200):
        a = rng.uniform(-1, 1, 3).astype(np.float32)
        o1, r1, _, _, i1 = env.step(a)
        o2, r2, _, _, i2 = plain.step(a)
        for key in ("xstar", "vstar", "N", "T", "slip_work", "reward_track"):
            assert i1[key] == i2[key], (k, key, i1[key], i2[key])
        assert i1["scene_draw"] == draw
        keep = [j for j in range(13) if j != 5]
        assert np.array_equal(o1[keep], o2[keep]), k
    sc = nominal
    wear_ref = sc.mu * sc.N_max * sc.creep_max * sc.omega_R_max * sc.dt  # nominal mu
    assert math.isclose(
        i1["reward_wear"], -sc.w_wear * i1["slip_work"] / wear_ref, rel_tol=1e-12, abs_tol=1e-300
    )


def test_draws_are_seeded():
    a = rolling_env.make(FAMILY)
    b = rolling_env.make(FAMILY)
    assert a.reset(seed=3)[1]["scene_draw"] == b.reset(seed=3)[1]["scene_draw"]
    assert a.reset(seed=4)[1]["scene_draw"] != b.reset(seed=3)[1]["scene_draw"]


def test_baselines_design_for_the_nominal_values():
    from agents.baselines import Eq32Feedback

    env = rolling_env.make(FAMILY)
    env.reset(seed=1)
    ctrl = Eq32Feedback.from_env(env)
    assert ctrl.scene.mu == 0.2 and ctrl.scene.runner_mass == 0.02 and ctrl.scene.F_ext == 0.0


def test_the_batched_envs_refuse_a_randomised_scene_and_training_takes_single_envs():
    from agents.vec_choice import choose_vec_env

    with pytest.raises(ValueError, match="randomize.*single envs"):
        gym.make_vec("RollingDrive-v0", num_envs=2, scene=FAMILY)
    kind, why = choose_vec_env("auto", FAMILY, 4, {}, measure=None)
    assert kind == "dummy" and "randomize" in why["chosen_by"]


@pytest.mark.parametrize(
    "spec,match",
    [
        ({"friction": [0.1, 0.2]}, r"'friction' cannot be drawn"),
        ({"mu": [0.4, 0.1]}, r"randomize.mu' must be finite \[low, high\]"),
        ({"mu": [0.1]}, r"randomize.mu' must be \[low, high\]"),
        ({"runner_mass": [0.0, 0.04]}, r"log-uniformly: low must be > 0"),
        ({"mu": [0.3, 0.4]}, r"'mu' = 0.2 .* must lie in its randomize range"),
        ({"mu": [0.1, "x"]}, r"randomize.mu'.*must be a number"),
        ("mu", r"must be a mapping of key: \[low, high\]"),
    ],
)
def test_bad_randomize_specs_are_one_line(spec, match):
    with pytest.raises(ValueError, match=match):
        load_scene("default", randomize=spec)


def test_every_corner_of_the_ranges_must_be_a_valid_scene():
    """A massless runner holds a load only below mu N_min: a load range reaching past it
    is refused at load time, not in some later episode."""
    with pytest.raises(ValueError, match=r"randomize': the draw .* invalid scene: .*F_ext"):
        load_scene("default", runner_mass=0.0, N_min=0.1, randomize={"F_ext": [-0.05, 0.0]})
