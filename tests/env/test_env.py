"""RollingDrive-v0 checked like Gymnasium's own envs (tests/envs/test_envs.py)."""

from __future__ import annotations

import math
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
import yaml

import rolling_env
from rolling_env.env.scenes import SCENE_DIR, load_scene

SCENES = rolling_env.list_scenes()


def test_shipped_scenes():
    assert set(SCENES) >= {"default", "heavy_inf_friction", "resonant", "light_stiff", "loaded"}


@pytest.mark.parametrize("scene", SCENES)
def test_gymnasium_check_env_no_warnings(scene):
    from gymnasium.utils.env_checker import check_env

    env = gym.make("RollingDrive-v0", scene=scene)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    msgs = [str(w.message) for w in caught]
    assert not msgs, f"gymnasium check_env warned on {scene}: {msgs}"


@pytest.mark.parametrize("scene", SCENES)
def test_sb3_check_env_no_warnings(scene):
    from stable_baselines3.common.env_checker import check_env

    env = gym.make("RollingDrive-v0", scene=scene).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, warn=True)
    msgs = [str(w.message) for w in caught]
    assert not msgs, f"SB3 check_env warned on {scene}: {msgs}"


def _rollout(env, seed, n=300):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    traj = [obs]
    for _ in range(n):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        traj.append(np.concatenate([obs, [r, info["xstar"], info["T"]]]))
        if term or trunc:
            obs, _ = env.reset()
    return traj


@pytest.mark.parametrize("scene", ["default", "resonant"])
def test_same_seed_bit_identical(scene):
    a = _rollout(gym.make("RollingDrive-v0", scene=scene), 123)
    b = _rollout(gym.make("RollingDrive-v0", scene=scene), 123)
    for x, y in zip(a, b):
        assert np.array_equal(x, y), "two envs with one seed must give bit-identical rollouts"


def test_pickle_round_trip_continues_identically():
    env = gym.make("RollingDrive-v0")
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, (60, 3)).astype(np.float32)
    for a in acts[:30]:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    for a in acts[30:]:
        o1, r1, *_ = env.step(a)
        o2, r2, *_ = clone.step(a)
        assert np.array_equal(o1, o2) and r1 == r2, "pickled env diverged from the original"


@pytest.mark.parametrize("copier", ["pickle", "deepcopy"])
def test_copied_env_resets_like_a_fresh_one(copier):
    """A copy made mid-episode must step and reset its own physics: its kernel views and
    the drive it resets are the same arrays."""
    import copy

    from rolling_env.env.drive_env import RollingDriveEnv

    env = RollingDriveEnv("default")
    env.reset(seed=1)
    for _ in range(300):
        env.step(np.array([1.0, 1.0, 1.0], np.float32))
    assert env.drive.xstar != 0.0, "the episode should have moved the runner"
    clone = pickle.loads(pickle.dumps(env)) if copier == "pickle" else copy.deepcopy(env)
    assert np.shares_memory(clone._arrays[0], clone.drive.U), "kernel views not re-bound"
    fresh = RollingDriveEnv("default")
    rng = np.random.default_rng(3)
    acts = rng.uniform(-1, 1, (200, 3)).astype(np.float32)
    for e in (clone, fresh):
        e.reset(seed=0)
    for a in acts:
        o1, r1, *_, i1 = clone.step(a)
        o2, r2, *_, i2 = fresh.step(a)
        assert np.array_equal(o1, o2) and r1 == r2 and i1 == i2, (
            f"{copier}d env after reset differs from a fresh env: reward {r1} vs {r2}"
        )
        assert clone.drive.xstar == i1["xstar"], "drive and kernel state out of step"


@pytest.mark.parametrize("copier", ["pickle", "deepcopy"])
def test_copy_of_a_rendered_env_renders_its_own_state(copier):
    """The figure an env drew with stays behind (an unpickled figure cannot draw): the copy
    draws its own, the same frame as the original's for the same state, and each then
    follows its own state."""
    import copy

    env = gym.make("RollingDrive-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.array([0.5, 0.5, 0.0], np.float32))
    first = env.render()
    clone = pickle.loads(pickle.dumps(env)) if copier == "pickle" else copy.deepcopy(env)
    frame = clone.render()
    assert frame.shape == first.shape and frame.dtype == np.uint8, (frame.shape, frame.dtype)
    assert np.array_equal(frame, first), "same state, different frame"
    for _ in range(20):
        clone.step(np.array([1.0, 1.0, 1.0], np.float32))
    assert not np.array_equal(clone.render(), env.render()), "the copy drew the original"
    clone.close()
    env.close()


@pytest.mark.parametrize("scene", SCENES)
def test_reward_is_exact_sum_of_terms(scene):
    env = gym.make("RollingDrive-v0", scene=scene)
    env.reset(seed=1)
    env.action_space.seed(1)
    for _ in range(200):
        _, r, _, _, info = env.step(env.action_space.sample())
        assert r == info["reward_track"] + info["reward_wear"], "reward != sum of its info terms"
        assert info["reward_wear"] <= 0.0 and info["reward_track"] <= 0.0


def test_truncation_by_time_limit_and_reset_after():
    env = gym.make("RollingDrive-v0", max_episode_steps=7)
    env.reset(seed=0)
    flags = [env.step(np.zeros(3, np.float32))[3] for _ in range(7)]
    assert flags == [False] * 6 + [True], f"TimeLimit must truncate at step 7: {flags}"
    obs, _ = env.reset()
    assert obs[9] == 0.0, "time fraction restarts at 0 after reset"
    _, _, term, trunc, _ = env.step(np.zeros(3, np.float32))
    assert not term and not trunc


@pytest.mark.parametrize(
    "make",
    [
        lambda **kw: gym.make("RollingDrive-v0", **kw),
        lambda **kw: rolling_env.make("default", **kw),
    ],
)
def test_episode_ends_at_the_scene_episode_steps(make):
    """gym.make and rolling_env.make truncate at the (overridden) episode_steps, exactly when
    the observation's time_fraction reaches 1."""
    env = make(episode_steps=11)
    env.reset(seed=0)
    for k in range(1, 12):
        obs, _, term, trunc, _ = env.step(np.zeros(3, np.float32))
        assert not term and trunc == (k == 11), f"step {k}: truncated={trunc}"
    assert obs[9] == 1.0, f"time_fraction at the end is {obs[9]}"
    env = make()
    env.reset(seed=0)
    flags = [env.step(np.zeros(3, np.float32))[3] for _ in range(512)]
    assert flags.index(True) == 511, "shipped scenes end after 512 steps"


def test_time_limit_longer_than_the_episode_is_rejected():
    with pytest.raises(
        ValueError,
        match=r"max_episode_steps must be an integer in \[1, 512\]"
        r".*episode_steps=1000",
    ):
        rolling_env.make("default", max_episode_steps=1000)
    with pytest.raises(ValueError, match="episode_steps"):
        gym.make_vec(
            "RollingDrive-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            max_episode_steps=1000,
        )


@pytest.mark.parametrize("bad", [0, -3, 2.5, math.inf, math.nan, True, "100", np.bool_(True), 1e20])
def test_bad_time_limits_are_rejected_without_the_lengthen_hint(bad):
    """Only a too-long limit that episode_steps can take (<= 1e8) suggests it; the rest get
    the range (inf was an OverflowError, True was accepted as 1)."""
    with pytest.raises(
        ValueError,
        match=r"max_episode_steps must be an integer in \[1, 512\]"
        r"[^;]*got",
    ) as e:
        rolling_env.make("default", max_episode_steps=bad)
    assert "lengthen" not in str(e.value), str(e.value)


def test_numpy_integer_and_integral_float_time_limits():
    """np.int64(5) and 5.0 are accepted and reach Gymnasium's TimeLimit as the int 5."""
    for m in (np.int64(5), 5.0):
        env = rolling_env.make("default", max_episode_steps=m)
        env.reset(seed=0)
        flags = [env.step(np.zeros(3, np.float32))[3] for _ in range(5)]
        assert flags == [False] * 4 + [True], f"max_episode_steps={m!r}: {flags}"


def test_target_option_and_sampled_range():
    env = gym.make("RollingDrive-v0")
    _, info = env.reset(seed=0, options={"target": 3e-7})
    assert info["target"] == 3e-7
    sc = load_scene("default")
    for s in range(20):
        _, info = env.reset(seed=s)
        assert sc.target_min <= abs(info["target"]) <= sc.target_max
    with pytest.raises(ValueError, match="target"):
        env.reset(options={"target": float("nan")})
    # the bound as written in the message is admitted (10 x 5e-7 rounds below 5e-6)
    _, info = env.reset(options={"target": -5e-6})
    assert info["target"] == -5e-6
    # a given target may have either sign where random draws have one only
    loaded = gym.make("RollingDrive-v0", scene="loaded")
    assert not loaded.unwrapped.scene.target_both_signs
    _, info = loaded.reset(seed=0, options={"target": -3e-7})
    assert info["target"] == -3e-7


@pytest.mark.parametrize(
    "bad",
    [
        np.array([np.nan, 0, 0]),
        np.array([0, np.inf, 0]),
        np.zeros(2),
        np.zeros((3, 1)),
        np.array([1.5, 0, 0]),
        np.array([1 + 2j, 0, 0]),
        np.array(["1", "0", "0"]),
        [True, False, False],
        [0.1, None, 0.0],
    ],
)
def test_bad_actions_raise(bad):
    env = gym.make("RollingDrive-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)


@pytest.mark.parametrize("scene", SCENES)
def test_random_fuzz_stays_finite(scene):
    """Thousands of random (and extreme corner) actions: every observation, reward and state
    stays finite and inside the observation bounds."""
    env = gym.make("RollingDrive-v0", scene=scene)
    env.reset(seed=7)
    rng = np.random.default_rng(7)
    corners = np.array([[1, 1, 1], [-1, -1, -1], [1, -1, 1], [-1, 1, -1]], np.float32)
    for k in range(3000):
        a = corners[k % 4] if (k // 50) % 3 == 0 else rng.uniform(-1, 1, 3).astype(np.float32)
        obs, r, term, trunc, info = env.step(a)
        assert np.all(np.isfinite(obs)) and np.isfinite(r), f"non-finite at step {k}"
        assert env.observation_space.contains(obs), f"obs out of bounds at step {k}"
        if trunc:
            env.reset()
    drv = env.unwrapped.drive
    assert np.all(np.isfinite(drv.U)) and np.all(np.isfinite(drv.st))


def test_scene_range_corners_build_and_stay_finite():
    """Scenes drawn at the ends of the allowed ranges (a few keys at a time): each either is
    rejected with a ValueError at construction or runs with finite observations, rewards and
    info values (in-range values such as period = 1e-200 s once crashed deep inside)."""
    from rolling_env.env.scenes import _SPEC

    keys = sorted(k for k, v in _SPEC.items() if v[0] is float)
    rng = np.random.default_rng(11)
    built = 0
    for trial in range(80):
        ov = {}
        for k in rng.choice(keys, size=rng.integers(1, 6), replace=False):
            _, lo, hi, _, _ = _SPEC[str(k)]
            pick = rng.integers(0, 3)
            top = hi if math.isfinite(hi) else 1e6  # inf (mu) itself is drawn as an end
            ov[str(k)] = (
                lo
                if pick == 0
                else hi
                if pick == 1
                else float(math.exp(rng.uniform(math.log(max(lo, 1e-300)), math.log(top))))
            )
        ov["sub_steps"] = int(rng.choice([1, 2, 8]))
        ov["resolution"] = float(rng.choice([1.0, 16.0]))
        try:
            env = gym.make("RollingDrive-v0", **ov)
        except ValueError:
            continue
        built += 1
        env.reset(seed=trial)
        for t in range(20):
            a = rng.choice([-1.0, 0.0, 1.0], 3) if t % 2 else rng.uniform(-1, 1, 3)
            obs, r, _, _, info = env.step(a.astype(np.float32))
            vals = [r] + [v for v in info.values() if isinstance(v, float)]
            assert np.all(np.isfinite(obs)) and all(math.isfinite(v) for v in vals), (
                f"non-finite output at step {t} with overrides {ov}"
            )
    assert built >= 20, f"only {built} of 80 corner scenes were valid: the sample tests little"


@pytest.mark.parametrize(
    "key,value",
    [
        ("period", 1e-200),
        ("G_star", 1e-300),
        ("N_max", 1e-320),
        ("omega_R_max", 5e-324),
        ("mu", 5e-324),
        ("target_max", 5e-324),
        ("R", 1e-300),
    ],
)
def test_scene_values_whose_scales_underflow_are_rejected(key, value):
    with pytest.raises(ValueError, match=f"scene key '{key}' must be in"):
        gym.make("RollingDrive-v0", **{key: value})


def test_scene_objects_are_checked_too():
    """A Scene built or replaced with dataclasses (bypassing Scene.replace) is checked like a
    file (period = 1e-200 crashed with ZeroDivisionError)."""
    import dataclasses

    bad = dataclasses.replace(load_scene("default"), period=1e-200)
    with pytest.raises(ValueError, match="scene key 'period' must be in"):
        gym.make("RollingDrive-v0", scene=bad)


def test_scene_elastic_constants_ratio_checked():
    with pytest.raises(ValueError, match=r"E_star/G_star in \[0.01, 100\]"):
        gym.make("RollingDrive-v0", E_star=1e13, G_star=1e3)


def test_stroke_saturation_reported():
    env = gym.make("RollingDrive-v0").unwrapped
    env.reset(seed=0)
    sat = []
    for _ in range(40):  # roll one way at full rate: the stroke limit must stop the patch
        _, _, _, _, info = env.step(np.array([0.5, 1.0, 0.2], np.float32))
        sat.append(info["saturation"])
        assert abs(env.drive.c) <= env.scene.stroke_roll * (1 + 1e-12)
    assert sat[0] == 1.0 and sat[-1] == 0.0 and any(0 < s < 1 for s in sat), sat


def test_render_rgb_array():
    env = gym.make("RollingDrive-v0", render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([0.5, 0.5, 0.5], np.float32))
    import matplotlib

    before = dict(matplotlib.rcParams)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 5, "frame should not be blank"
    changed = {k for k, v in matplotlib.rcParams.items() if before.get(k) != v}
    assert not changed, f"rendering changed the caller's matplotlib settings: {changed}"


# ----------------------------------------------------------------------------- scenes
def _raw(name="default"):
    with open(SCENE_DIR / f"{name}.yaml") as f:
        return yaml.safe_load(f)


@pytest.mark.parametrize(
    "mutate,match",
    [
        (lambda d: d.update(bogus=1), "unknown scene key 'bogus'"),
        (lambda d: d.pop("mu"), "missing key"),
        (lambda d: d.update(mu="lots"), "'mu' must be a number"),
        (lambda d: d.update(runner_mass=-1.0), "'runner_mass' must be in"),
        (lambda d: d.update(sub_steps=2.5), "'sub_steps' must be an integer"),
        (lambda d: d.update(target_both_signs="yes"), "'target_both_signs' must be true or false"),
        (lambda d: d.update(N_min=2.0), "'N_min' must be < N_max"),
        (lambda d: d.update(name="../../x"), "'name' must be a file name"),
        (lambda d: d.update(name=""), "'name' must be a file name"),
    ],
)
def test_scene_validation(mutate, match):
    d = _raw()
    mutate(d)
    with pytest.raises(ValueError, match=match):
        load_scene(d)


def test_scene_file_errors_name_the_file(tmp_path):
    """A YAML syntax error or a key given twice is a ValueError naming the file (not a yaml
    traceback, and not the last duplicate silently winning)."""
    broken = tmp_path / "broken.yaml"
    broken.write_text("a: [1\n")
    with pytest.raises(ValueError, match="broken.yaml' is not valid YAML"):
        load_scene(broken)
    text = (SCENE_DIR / "default.yaml").read_text()
    dup = tmp_path / "dup.yaml"
    dup.write_text(text + "mu: 0.5\n")
    with pytest.raises(ValueError, match="duplicate key 'mu'"):
        load_scene(dup)
    from rolling_env.env.scenes import _UniqueKeyLoader

    doc = "a: {<<: {p: 1, q: 2}, p: 3}\nb: {<<: [{p: 1}, {p: 2, q: 1}], r: 1}"
    assert yaml.load(doc, Loader=_UniqueKeyLoader) == yaml.safe_load(doc), (
        "a key overriding a merged one is not a duplicate"
    )
    merged = tmp_path / "merged.yaml"  # YAML merge keys work as with yaml.safe_load
    merged.write_text(text.replace("w_wear: 0.5", "w_wear: 0.5\nx: &a {p: 1}\ny: {<<: *a}"))
    with pytest.raises(ValueError, match="unknown scene key 'x'"):
        load_scene(merged)
    unhashable = tmp_path / "unhashable.yaml"
    unhashable.write_text("? [1, 2]\n: 3\n" + text)
    with pytest.raises(ValueError, match="unhashable.yaml' is not valid YAML"):
        load_scene(unhashable)
    ok = tmp_path / "ok.yaml"
    ok.write_text(text)
    assert load_scene(ok) == load_scene("default").replace(name="default"), (
        "a copy of a shipped scene must load unchanged"
    )


def test_overrides_validated_and_applied():
    env = gym.make("RollingDrive-v0", mu=0.1, runner_mass=0.01)
    assert env.unwrapped.scene.mu == 0.1 and env.unwrapped.scene.runner_mass == 0.01
    with pytest.raises(ValueError, match="'mu' must be in"):
        gym.make("RollingDrive-v0", mu=-1.0)
    with pytest.raises(ValueError, match="unknown scene"):
        gym.make("RollingDrive-v0", scene="nope")


def test_scene_features_pick_the_kernel():
    """Leaving out: infinite friction keeps no friction-limit array, no load keeps no load term."""
    inf = gym.make("RollingDrive-v0", scene="heavy_inf_friction").unwrapped.drive
    loaded = gym.make("RollingDrive-v0", scene="loaded").unwrapped.drive
    assert inf._mu is None and inf.L.shape[0] == 0 and inf.cells.shape[0] == 3, (
        f"infinite friction keeps {inf.L.shape[0]} friction rows"
    )
    assert inf._load is None
    assert loaded._mu is not None and loaded._load is not None


def test_registration_without_import():
    code = (
        "import gymnasium as gym; env = gym.make('rolling_env:RollingDrive-v0'); "
        "env.reset(seed=0); print(env.step(env.action_space.sample())[0].shape)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(13,)", out.stderr


def test_kernel_action_mapping_matches_documented_mapping():
    """The compiled env tick maps actions exactly as rolling_env.env.actions.to_controls
    documents."""
    from rolling_env.env.actions import from_controls, to_controls

    env = gym.make("RollingDrive-v0").unwrapped
    env.reset(seed=0)
    for a in np.random.default_rng(1).uniform(-0.2, 0.2, (20, 3)):
        info = env.step(a.astype(np.float32))[4]
        N, u, v = to_controls(env.scene, a.astype(np.float32).astype(np.float64))
        assert info["saturation"] == 1.0
        assert abs(info["N"] - N) < 1e-12 * N and info["omega_R"] == u and info["v"] == v
        back = from_controls(env.scene, N, u, 1 - v / u)
        assert np.allclose(back, a, atol=1e-6)


def test_env_leaves_the_energy_ledger_out_and_says_so():
    """The env kernel skips the impulse/energy bookkeeping the env does not use; asking the env's
    drive for energies is an error, not silent zeros."""
    env = gym.make("RollingDrive-v0")
    env.reset(seed=0)
    env.step(np.array([0.5, 0.5, 0.1], np.float32))
    with pytest.raises(RuntimeError, match="ledger"):
        env.unwrapped.drive.energy


@pytest.mark.parametrize("scene", ["default", "heavy_inf_friction"])
def test_denormal_rolling_action_right_after_reset(scene):
    """A valid action whose rolling rate is a subnormal number, straight after reset (patch at
    the cell boundary c = 0), gives a finite step, not an error."""
    env = gym.make("RollingDrive-v0", scene=scene)
    env.reset(seed=0)
    obs, reward, *_ = env.step(np.array([0.5, 1e-310, 0.0]))
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)


def test_numpy_scalar_overrides_and_scene_types():
    """Overrides from numpy sweeps (np.float32, np.int64) are numbers like any other; a scene
    that is not a name, path, dict or Scene is a ValueError listing what is allowed."""
    env = gym.make(
        "RollingDrive-v0", mu=np.float32(0.25), sub_steps=np.int64(4), resolution=np.int64(8)
    )
    sc = env.unwrapped.scene
    assert sc.mu == pytest.approx(0.25) and sc.sub_steps == 4 and type(sc.sub_steps) is int
    with pytest.raises(ValueError, match=r"'sub_steps' must be an integer in \[1, 100000\], got 0"):
        gym.make("RollingDrive-v0", sub_steps=np.int64(0))
    with pytest.raises(ValueError, match="'mu' must be a number"):
        gym.make("RollingDrive-v0", mu=np.bool_(True))
    sc = gym.make("RollingDrive-v0", target_both_signs=np.bool_(False)).unwrapped.scene
    assert sc.target_both_signs is False, "a numpy bool is a bool key's value like True/False"
    with pytest.raises(ValueError, match="'target_both_signs' must be true or false"):
        gym.make("RollingDrive-v0", target_both_signs=1)
    for bad in (3, None):
        with pytest.raises(ValueError, match="scene must be a shipped scene name"):
            gym.make("RollingDrive-v0", scene=bad)
    with pytest.raises(ValueError, match="'E_star'"):
        gym.make("RollingDrive-v0", E_star=1.0)


def test_vanishing_runner_mass_tends_to_massless():
    """runner_mass = 1e-100 kg is a valid scene value and must behave like 0 (massless): the
    same trajectory to 1e-9 of its size (it once drifted to x* ~ -1e27 m with finite friction)."""
    runs = {}
    for m in (0.0, 1e-100):
        env = gym.make("RollingDrive-v0", runner_mass=m)
        env.reset(seed=3)
        env.action_space.seed(3)
        runs[m] = np.array([env.step(env.action_space.sample())[4]["xstar"] for _ in range(200)])
    scale = np.max(np.abs(runs[0.0]))
    err = np.max(np.abs(runs[1e-100] - runs[0.0]))
    assert scale > 0 and err <= 1e-9 * scale, f"x* differs by {err:.3g} m (scale {scale:.3g} m)"


@pytest.mark.parametrize(
    "options,match",
    [
        (
            {"target": 1e-3},
            r"options\['target'\] must be a finite displacement in "
            r"\[-5e-06, 5e-06\]",
        ),
        ({"target": 5.001e-6}, r"in \[-5e-06, 5e-06\] m .*got 5.001e-06"),
        ({"target": True}, r"options\['target'\] must be a number"),
        ({"target": 10**400}, r"options\['target'\] .* got an integer too large for a float"),
        ({"target": float("nan")}, "finite displacement"),
        ({"targte": 1e-7}, r"unknown key\(s\) \['targte'\]"),
        ({"target": "3e-7"}, r"options\['target'\] must be a number"),
        ([{"target": 1e-7}], "options must be a dict"),
    ],
)
def test_reset_target_option_checked_before_anything_changes(options, match):
    """A target the error observation cannot show (beyond OBS_BOUND target_max it sits at its
    clip all episode), a boolean, a mistyped key: ValueError, and the env's generator is not
    reseeded (it was, before the option raised)."""
    env = gym.make("RollingDrive-v0")
    env.reset(seed=1)
    state = env.unwrapped.np_random.bit_generator.state
    with pytest.raises(ValueError, match=match):
        env.reset(seed=2, options=options)
    assert env.unwrapped.np_random.bit_generator.state == state
    from types import MappingProxyType

    env.reset(options=MappingProxyType({"target": np.array(3e-7)}))  # any mapping, 0-d arrays
    assert env.unwrapped.target == 3e-7
    edge = -10 * env.unwrapped.scene.target_max  # OBS_BOUND x target_max: still allowed
    obs, _ = env.reset(options={"target": edge})
    assert obs[0] == -10.0 and env.unwrapped.target == edge


def test_history_kept_only_for_rendering():
    """Without a render_mode the env keeps no per-step history (it grew ~39 MB per 1e6 steps)."""
    env = gym.make("RollingDrive-v0")
    env.reset(seed=0)
    for _ in range(20):
        env.step(env.action_space.sample())
    assert env.unwrapped._history == []
    env = gym.make("RollingDrive-v0", render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(20):
        env.step(env.action_space.sample())
    assert len(env.unwrapped._history) == 21 and env.render().ndim == 3


def test_human_render_windows_are_per_env():
    """Two envs rendering to windows each get their own; closing one keeps the other's (they
    shared one module-level window)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.close("all")
    envs = [gym.make("RollingDrive-v0", render_mode="human") for _ in range(2)]
    for e in envs:
        e.reset(seed=0)
        e.step(np.zeros(3, np.float32))
    assert len(plt.get_fignums()) == 2
    envs[0].close()
    assert len(plt.get_fignums()) == 1
    envs[1].step(np.zeros(3, np.float32))
    envs[1].close()
    assert plt.get_fignums() == []


def test_seeded_targets_are_those_of_rng_choice():
    """Reproducibility: the targets a seed gives (and the generator state after them) are
    those of the first implementation, which drew the sign with rng.choice((-1.0, 1.0));
    sample_target draws the same integer without choice's conversion of the tuple."""
    from rolling_env.env.drive_env import sample_target

    scene = load_scene("default")
    assert scene.target_both_signs
    for seed in range(300):
        ours, ref = np.random.default_rng(seed), np.random.default_rng(seed)
        for _ in range(4):
            got = sample_target(scene, ours, None)
            mag = ref.uniform(scene.target_min, scene.target_max)
            want = float(ref.choice((-1.0, 1.0)) * mag)
            assert got == want, f"seed {seed}: target {got!r}, rng.choice gives {want!r}"
        assert ours.bit_generator.state == ref.bit_generator.state, f"seed {seed}: state differs"


def test_unreadable_scene_files_are_value_errors_naming_the_file(tmp_path):
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00name: x\n")
    with pytest.raises(ValueError, match=r"binary.yaml' is not UTF-8 text"):
        load_scene(binary)
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    with pytest.raises(ValueError, match=r"folder.yaml' cannot be read"):
        load_scene(folder)


def test_overflow_of_a_light_loaded_runner_names_the_scene_keys():
    """A legal but absurd scene (a 1e-295 kg runner under 1e6 N, free while the contact
    lifts off) overflows on its first step: the error says which keys make it do so, in the
    single and the batched env."""
    from rolling_env.env.vector import BatchCore

    kw = dict(runner_mass=1e-295, F_ext=1e6, period=1e3, ticks_per_period=2)
    env = gym.make("RollingDrive-v0", **kw)
    env.reset(seed=0)
    with pytest.raises(FloatingPointError, match=r"runner_mass = 1e-295 kg under F_ext = 1e\+06"):
        env.step(np.zeros(3, np.float32))
    core = BatchCore(2, **kw)
    core.seed(0)
    core.reset()
    with pytest.raises(FloatingPointError, match=r"raise runner_mass or lower \|F_ext\|"):
        core.step(np.zeros((2, 3)))


def test_scene_inputs_beyond_the_float_range_and_suffix_case(tmp_path):
    """An integer beyond the float range (10**400) raised a bare OverflowError naming no key;
    a scene file whose suffix is upper case (.YAML) was taken for an unknown scene name; a
    0-d array override was refused while numpy scalars were taken."""
    from rolling_env.env.scenes import SCENE_DIR

    for key in ("episode_steps", "R"):
        with pytest.raises(ValueError, match=f"^scene key '{key}' must be"):
            rolling_env.make("default", **{key: 10**400})
    assert rolling_env.make("default", R=np.array(2e-3)).unwrapped.scene.R == 2e-3
    upper = tmp_path / "Mine.YAML"
    upper.write_text((SCENE_DIR / "resonant.yaml").read_text())
    assert rolling_env.make(str(upper)).unwrapped.scene.name == "resonant"


def test_friction_coefficient_beyond_the_float_range_still_sticks():
    """mu = 1.7e308 is a valid scene value whose mu E*/G* overflows to an inf friction limit:
    no cell slides, and the stick fraction (observation 6 and the info) reads 1, as for mu =
    1e300 (it read 0, 'all slipping', when the stick test compared -inf < -inf).  The wear is
    then only the elastic energy the material carries out at the trailing edge (where its
    limit vanishes, however large mu): the same for both, finite, and positive once the
    contact has rolled."""
    slips = []
    for mu in (1e300, 1.7e308):
        env = gym.make("RollingDrive-v0", mu=mu)
        env.reset(seed=0)
        for _ in range(3):
            obs, _, _, _, info = env.step(np.array([1.0, 0.5, 0.5], np.float32))
            assert info["stick_fraction"] == 1.0 and obs[6] == 1.0, (mu, info["stick_fraction"])
        assert math.isfinite(info["slip_work"]) and info["slip_work"] > 0.0, info["slip_work"]
        slips.append(info["slip_work"])
    assert slips[0] == pytest.approx(slips[1], rel=1e-12), slips


def test_a_scene_that_cannot_be_built_names_its_keys():
    """A scene whose every key is in range but whose spring row would be too long (stroke 1 m
    at 4096 cells per contact radius): the error names the scene and the keys behind the
    drive's arguments, not only 'the stroke' and 'a_ref'."""
    scene = load_scene("default", stroke_roll=0.5, resolution=4096.0)
    with pytest.raises(
        ValueError,
        match=r"^scene 'default' cannot be built: .*cells.*"
        r"stroke_roll = 0.5 m.*N_max.*resolution = 4096",
    ):
        gym.make("RollingDrive-v0", scene=scene)
