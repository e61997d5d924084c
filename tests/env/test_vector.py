"""The natively batched env against N single envs: bit-identical transitions."""

from __future__ import annotations

import re
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import rolling_env
import rolling_env.env._envkernel as EK
from rolling_env.env.sb3_vec import RollingDriveVecEnv
from rolling_env.env.threads import PARALLEL_MIN_ENVS, ThreadPolicy, max_threads
from rolling_env.env.vector import BatchCore

STEPS = 40  # with max_episode_steps = 15: crosses two episode boundaries
THREADS = min(2, max_threads())  # the threaded kernel's thread count in these tests
# batch sizes and num_threads that take the serial kernel (the default below
# ``PARALLEL_MIN_ENVS`` envs), the threaded kernel, and the default's run-time choice
KERNELS = pytest.mark.parametrize(
    "n,num_threads",
    [(3, None), (PARALLEL_MIN_ENVS, THREADS), (PARALLEL_MIN_ENVS, None)],
    ids=["serial", "threaded", "default"],
)


def _kernel_of(core, n, num_threads):
    if num_threads is None and n < PARALLEL_MIN_ENVS:
        assert core._step_fn is EK.env_step_serial, f"{n} envs step with {core._step_fn}"
    elif num_threads is None:
        assert isinstance(core.thread_policy, ThreadPolicy) or max_threads() == 1
    else:
        assert core.threads == num_threads and core.thread_policy is None


def _actions(seed, n, steps=STEPS):
    return np.random.default_rng(seed).uniform(-1, 1, (steps, n, 3)).astype(np.float32)


@KERNELS
@pytest.mark.parametrize("scene", ["default", "resonant", "heavy_inf_friction", "loaded"])
def test_gymnasium_vector_env_matches_single_envs(scene, n, num_threads):
    venv = gym.make_vec(
        "RollingDrive-v0",
        num_envs=n,
        vectorization_mode="vector_entry_point",
        scene=scene,
        max_episode_steps=15,
        num_threads=num_threads,
    )
    _kernel_of(venv.unwrapped.core, n, num_threads)
    singles = [gym.make("RollingDrive-v0", scene=scene, max_episode_steps=15) for _ in range(n)]
    vobs, _ = venv.reset(seed=7)
    sobs = np.stack([e.reset(seed=7 + i)[0] for i, e in enumerate(singles)])
    assert np.array_equal(vobs, sobs), "reset observations differ"
    done = np.zeros(n, bool)
    for acts in _actions(1, n):
        vobs, vrew, vterm, vtrunc, _ = venv.step(acts)
        for i, e in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: this step resets env i
                o, _ = e.reset()
                r, te, tr = 0.0, False, False
            else:
                o, r, te, tr, _ = e.step(acts[i])
            assert np.array_equal(vobs[i], o), f"obs of env {i} differ"
            assert vrew[i] == r and vterm[i] == te and vtrunc[i] == tr, f"env {i} differs"
        done = vterm | vtrunc
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP


@KERNELS
@pytest.mark.parametrize("scene", ["default", "light_stiff"])
def test_sb3_vecenv_matches_single_envs(scene, n, num_threads):
    venv = RollingDriveVecEnv(n, scene=scene, max_episode_steps=15, num_threads=num_threads)
    _kernel_of(venv.core, n, num_threads)
    venv.seed(3)
    vobs = venv.reset()
    singles = [gym.make("RollingDrive-v0", scene=scene, max_episode_steps=15) for _ in range(n)]
    sobs = np.stack([e.reset(seed=3 + i)[0] for i, e in enumerate(singles)])
    assert np.array_equal(vobs, sobs)
    for acts in _actions(2, n):
        vobs, vrew, vdone, infos = venv.step(acts)
        for i, e in enumerate(singles):
            o, r, te, tr, info = e.step(acts[i])
            assert np.float32(r) == vrew[i] and vdone[i] == (te or tr)
            assert info["reward_track"] == infos[i]["reward_track"]
            if te or tr:  # SAME_STEP: terminal obs in info, reset obs returned
                assert np.array_equal(infos[i]["terminal_observation"], o)
                assert infos[i]["TimeLimit.truncated"] == (tr and not te)
                o, _ = e.reset()
            assert np.array_equal(vobs[i], o), f"obs of env {i} differ"


def test_reset_mask_resets_only_masked():
    core = BatchCore(3, max_episode_steps=100)
    core.seed(0)
    core.reset()
    for _ in range(5):
        core.step(np.full((3, 3), 0.5))
    names = ("st", "U", "extra", "obs", "target", "steps")
    before = {k: getattr(core, k).copy() for k in names}
    assert np.any(core.U[1] != 0.0) and np.any(core.extra[1] != 0.0), "nothing to reset"
    core.reset(np.array([False, True, False]))
    for k in names:  # the other envs keep every per-env array
        for e in (0, 2):
            assert np.array_equal(getattr(core, k)[e], before[k][e]), f"{k}[{e}] changed"
    assert np.all(core.st[1] == 0.0) and core.steps[1] == 0 and core.steps[0] == 5
    assert np.all(core.U[1] == 0.0), "masked env kept tangential content"
    sat = np.zeros(EK.N_X)
    sat[EK.X_SAT] = 1.0
    assert np.array_equal(core.extra[1], sat), core.extra[1]
    expect = np.zeros(EK.N_OBS, dtype=np.float32)  # runner at rest, no contact, step 0
    expect[0] = core.target[1] / core.scene.target_max
    expect[8] = 1.0
    assert np.array_equal(core.obs[1], expect), (core.obs[1], expect)


@pytest.mark.parametrize(
    "mask",
    [
        [2],
        np.array([2]),
        "abc",
        np.array([0, 1, 0]),
        np.array([False, True, False, False, True]),
        np.array([[False, True, False]]),
    ],
)
def test_reset_mask_must_be_one_bool_per_env(mask):
    """An index list ([2], read as 'True at env 0' by flatnonzero), a string, an int array or
    a bool array of another shape reset the wrong env or half-reset one (the target drawn,
    the physics kept): a ValueError naming mask and its shape, with nothing changed."""
    core = BatchCore(3, max_episode_steps=100)
    core.seed(0)
    core.reset()
    core.step(np.full((3, 3), 0.5))
    before = {k: getattr(core, k).copy() for k in ("st", "U", "target", "steps")}
    state = [r.bit_generator.state for r in core.rngs]
    with pytest.raises(ValueError, match=r"^mask must be None or a bool array of shape \(3,\)"):
        core.reset(mask)
    for k, v in before.items():
        assert np.array_equal(getattr(core, k), v), f"{k} changed by a refused reset"
    assert [r.bit_generator.state for r in core.rngs] == state, "a generator advanced"


@pytest.mark.skipif(THREADS < 2, reason="numba runs one thread here")
def test_parallel_kernel_equals_serial():
    a, b = BatchCore(70, num_threads=THREADS), BatchCore(70, num_threads=1)
    assert b._step_fn is EK.env_step_serial and a._step_fn is not EK.env_step_serial
    a.seed(1), b.seed(1)
    a.reset(), b.reset()
    for acts in _actions(4, n=70, steps=10):
        oa, ra, _ = a.step(acts)
        ob, rb, _ = b.step(acts)
        assert np.array_equal(oa, ob) and np.array_equal(ra, rb)


@pytest.mark.parametrize(
    "num_envs,num_threads",
    [(3, 1), (70, THREADS), (70, None)],
    ids=["serial", "threaded", "default"],
)
def test_step_returns_the_kernels_reward_and_truncation_as_copies(num_envs, num_threads):
    """``BatchCore.step`` returns the reward and ``steps >= max_episode_steps`` that the kernel
    writes per env: equal to the extras' reward column and to the step counts compared in
    numpy, also after the limit changes mid-episode (SB3's set_attr does that) and for envs
    reset at different times; and as copies that the next step does not overwrite."""
    core = BatchCore(num_envs, max_episode_steps=12, num_threads=num_threads)
    core.seed(3)
    core.reset()
    kept = []
    for k, acts in enumerate(_actions(5, n=num_envs, steps=30)):
        if k == 20:
            core.max_episode_steps = 7  # ends the running episodes at their next step
        obs, rew, trunc = core.step(acts)
        assert np.array_equal(rew, core.extra[:, EK.X_REWARD]), f"step {k}: reward differs"
        assert np.array_equal(trunc, core.steps >= core.max_episode_steps), (
            f"step {k}: truncation {trunc.astype(int)} vs steps {core.steps}"
        )
        assert trunc.dtype == np.bool_ and rew.dtype == np.float64
        kept.append((rew, rew.copy(), trunc, trunc.copy()))
        if k == 5:
            core.reset(np.arange(num_envs) % 2 == 0)  # half the envs start over early
        if np.count_nonzero(trunc):
            core.reset(trunc)
    assert any(t.any() for _, _, t, _ in kept) and not all(t.all() for _, _, t, _ in kept)
    for k, (r, r0, t, t0) in enumerate(kept):
        assert np.array_equal(r, r0) and np.array_equal(t, t0), f"step {k}'s output changed"


def test_bad_batch_actions_raise():
    core = BatchCore(2)
    core.reset()
    with pytest.raises(ValueError, match="action"):
        core.step(np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="shape"):
        core.step(np.zeros((3, 3)))


def test_sb3_trains_on_batched_env():
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env  # noqa: F401
    from stable_baselines3.common.vec_env import VecCheckNan, VecMonitor

    venv = VecCheckNan(
        VecMonitor(RollingDriveVecEnv(8, max_episode_steps=64)), raise_exception=True
    )
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(512)
    assert model.num_timesteps >= 512


@pytest.mark.parametrize("num_envs", [1, 6])
def test_kernel_errors_raise_in_single_and_batched_env(num_envs):
    """A kernel error flag in any env of the batch raises the same error as in the single env:
    the contact off the spring row -> RuntimeError, a non-finite state -> FloatingPointError;
    the batch's message names the env that failed (it named none: the user had to search the
    state for it), and a reset of that env alone lets the batch go on."""
    from rolling_env.physics import _kernel as K

    core = BatchCore(num_envs, scene="default")
    core.reset()
    core.st[-1, K.ST_C] = 1e6  # patch far outside the spring row
    which = re.escape(f"in 1 of the batch's {num_envs} envs: {num_envs - 1};")
    with pytest.raises(RuntimeError, match=f"spring row.*{which}"):
        core.step(np.zeros((num_envs, 3)))
    core.reset()
    core.step(np.tile([0.5, 0.5, 0.1], (num_envs, 1)))
    core.U[-1, :] = np.nan  # a corrupted deflection in the last env
    with pytest.raises(FloatingPointError, match=which):
        core.step(np.tile([0.5, 0.5, 0.1], (num_envs, 1)))
    mask = np.zeros(num_envs, dtype=bool)
    mask[-1] = True
    core.reset(mask)
    obs, rew, _ = core.step(np.tile([0.5, 0.5, 0.1], (num_envs, 1)))
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew)), "the reset env did not recover"
    env = gym.make("RollingDrive-v0")
    env.reset(seed=0)
    env.unwrapped.drive.st[K.ST_C] = 1e6
    with pytest.raises(RuntimeError, match="spring row"):
        env.step(np.zeros(3, np.float32))


def test_sb3_vecenv_per_env_options_and_indices():
    """set_options with one dict per env, get_attr/set_attr/env_method honour indices."""
    v = RollingDriveVecEnv(3)
    v.set_options([{"target": 1e-7}, {"target": 2e-7}, {}])
    v.seed(5)
    v.reset()
    assert v.core.target[0] == 1e-7 and v.core.target[1] == 2e-7, v.core.target
    assert v.core.target[2] not in (1e-7, 2e-7)
    assert v.get_attr("target", indices=[1]) == [2e-7]
    assert v.get_attr("num_envs") == [3, 3, 3]
    before = v.core.target.copy()
    v.core.steps[:] = 7
    v.env_method("reset", indices=[0])
    assert v.core.steps.tolist() == [0, 7, 7], "reset with indices must reset only those envs"
    assert v.core.target[1:].tolist() == before[1:].tolist()
    v.set_attr("target", 3e-7, indices=[2])
    assert v.core.target[2] == 3e-7 and v.core.target[1] == 2e-7
    with pytest.raises(AttributeError, match="'sv' is fixed when the batch is built"):
        v.set_attr("sv", 0.0, indices=[1])
    with pytest.raises(NotImplementedError, match="shared by every env"):
        v.set_attr("max_episode_steps", 100, indices=[1])
    with pytest.raises(NotImplementedError, match="whole batch"):
        v.env_method("seed", 1, indices=[1])


def test_shared_attributes_stay_shared_whatever_the_batch_size():
    """Per-env or shared is decided by name, not by a leading length that happens to equal
    num_envs: with as many envs as the scene vector has entries, ``sv`` is still shared and
    the per-env random generators are still per env."""
    core = RollingDriveVecEnv(1).core
    n = core.sv.shape[0]
    v = RollingDriveVecEnv(n)
    sv = v.get_attr("sv", indices=[1])[0]
    assert isinstance(sv, np.ndarray) and sv.shape == (n,), "sv was split per env"
    rngs = v.get_attr("rngs", indices=[0, 2])
    assert rngs[0] is v.core.rngs[0] and rngs[1] is v.core.rngs[2]
    with pytest.raises(AttributeError, match="'sv' is fixed when the batch is built"):
        v.set_attr("sv", sv, indices=[1])


def test_per_env_names_every_array_with_an_env_axis():
    """``BatchCore.PER_ENV`` (which SB3's get_attr slices per env and set_attr refuses as
    physics state) names exactly the attributes and properties with one entry per env: with 3
    envs (no shared array has 3 rows), every array or list of length 3 is in it and everything
    in it has length 3.  And get_attr("cells") gives each env its own rows."""
    v = RollingDriveVecEnv(3)
    core = v.core
    names = set(vars(core)) | {
        k for cls in BatchCore.__mro__ for k, x in vars(cls).items() if isinstance(x, property)
    }
    per_env = {
        k
        for k in names
        if isinstance(getattr(core, k), (np.ndarray, list)) and len(getattr(core, k)) == 3
    }
    assert per_env == set(BatchCore.PER_ENV), (
        f"per-env attributes not in PER_ENV: {sorted(per_env - BatchCore.PER_ENV)}; "
        f"in PER_ENV but not per env: {sorted(BatchCore.PER_ENV - per_env)}"
    )
    cells = v.get_attr("cells", indices=[1])[0]
    assert cells.shape == core.cells.shape[1:] and np.shares_memory(cells, core.cells[1])
    with pytest.raises(AttributeError, match="read-only|per-env"):
        v.set_attr("cells", 0.0, indices=[0])


@pytest.mark.parametrize(
    "name,value", [("scene", "resonant"), ("num_envs", 5), ("features", (None, None, None, None))]
)
def test_sb3_set_attr_refuses_what_is_fixed_at_construction(name, value):
    """Setting the scene (the kernel kept the old physics: trajectories stayed those of the
    old scene while get_attr reported the new one) or the batch size (arrays too short) is
    refused, and nothing changes."""
    v = RollingDriveVecEnv(2)
    before = getattr(v.core, name)
    with pytest.raises(AttributeError, match=f"'{name}' is fixed when the batch is built"):
        v.set_attr(name, value)
    assert getattr(v.core, name) is before


def test_gymnasium_vector_env_accepts_a_list_of_seeds():
    """reset(seed=[s0, s1, ...]) seeds env i with s_i, like Gymnasium's own vector envs."""
    venv = gym.make_vec("RollingDrive-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs_list, _ = venv.reset(seed=[4, 9, 2])
    for i, s in enumerate([4, 9, 2]):
        single, _ = gym.make("RollingDrive-v0").reset(seed=s)
        np.testing.assert_array_equal(obs_list[i], single, err_msg=f"env {i} seeded {s}")
    with pytest.raises(ValueError, match="num_envs = 3"):
        venv.reset(seed=[1, 2])


def test_seeds_are_checked_integers():
    """A numpy integer seeds like the int it equals; a fractional, negative or boolean seed
    is an error naming it (1.5 was truncated to 1)."""
    venv = gym.make_vec("RollingDrive-v0", num_envs=2, vectorization_mode="vector_entry_point")
    a, _ = venv.reset(seed=np.int64(7))
    b, _ = venv.reset(seed=7)
    np.testing.assert_array_equal(a, b)
    for bad, name in ((1.5, "seed"), (-1, "seed"), (True, "seed"), ([3, 2.5], r"seed\[1\]")):
        with pytest.raises(ValueError, match=f"{name} must be a non-negative integer"):
            venv.reset(seed=bad)
    c, _ = venv.reset(seed=np.array(7))  # a 0-d array is the integer it holds
    np.testing.assert_array_equal(c, a)
    sb3_env = RollingDriveVecEnv(2)
    sb3_env.seed(np.int64(7))
    np.testing.assert_array_equal(sb3_env.reset(), a)
    with pytest.raises(ValueError, match=r"max_episode_steps must be an integer in \[1, 512\]"):
        sb3_env.set_attr("max_episode_steps", 10**9)
    sb3_env.set_attr("max_episode_steps", 100)
    assert sb3_env.core.max_episode_steps == 100


def test_gymnasium_vector_infos_match_sync_mode():
    """The batched vector env reports the single env's info keys (error, vstar, N, T,
    saturated, ...) with Gymnasium's _key masks, equal to "sync" mode's at every step,
    autoreset steps included (it reported 5 of the 14 keys)."""
    kw = dict(num_envs=3, episode_steps=6)
    ours = gym.make_vec("RollingDrive-v0", vectorization_mode="vector_entry_point", **kw)
    sync = gym.make_vec("RollingDrive-v0", vectorization_mode="sync", **kw)

    def same(a, b, when):
        assert set(a) == set(b), f"{when}: keys differ: {set(a) ^ set(b)}"
        for k in b:
            assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]), (
                f"{when}: info[{k!r}] differs: {a[k]} vs {b[k]}"
            )

    same(ours.reset(seed=3)[1], sync.reset(seed=3)[1], "reset")
    for t, acts in enumerate(_actions(2, n=3, steps=14)):
        (o1, *_, a), (o2, *_, b) = ours.step(acts), sync.step(acts)
        assert np.array_equal(o1, o2)
        same(a, b, f"step {t}")
    for t, acts in enumerate(_actions(3, n=3, steps=20)):  # until every env has just ended
        (o1, _, _, tr1, a), (o2, _, _, tr2, b) = ours.step(acts), sync.step(acts)
        if tr1.all():
            break
    assert tr1.all() and tr2.all(), "the episodes should end together (episode_steps = 6)"
    mask = np.array([False, True, False])  # Gymnasium's partial reset; envs 0, 2 stay pending
    (o1, a), (o2, b) = (
        ours.reset(seed=[1, 11, 2], options={"reset_mask": mask.copy()}),
        sync.reset(seed=[1, 11, 2], options={"reset_mask": mask.copy()}),
    )
    assert np.array_equal(o1, o2), "partial reset: observations differ"
    same(a, b, "partial reset")
    for t, acts in enumerate(_actions(4, n=3, steps=8)):
        s1, s2 = ours.step(acts), sync.step(acts)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated"), s1[:4], s2[:4]):
            assert np.array_equal(x, y), f"after the partial reset, step {t}: {name} differ"
        same(s1[4], s2[4], f"after the partial reset, step {t}")
    with pytest.raises(ValueError, match=r"options\['reset_mask'\] must be a numpy bool array"):
        ours.reset(options={"reset_mask": [True, False, False]})


def test_gymnasium_vector_env_checks_action_types():
    """Strings and booleans are rejected like the single env does (they were cast to float)."""
    venv = gym.make_vec("RollingDrive-v0", num_envs=2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    for bad in ([["1", "0.5", "0"]] * 2, np.ones((2, 3), bool)):
        with pytest.raises(ValueError, match="action must be real numbers"):
            venv.step(bad)


def test_batch_reset_with_a_bad_option_changes_nothing():
    """All options are checked before any env is reset (env 0 was reset before env 1's bad
    option raised)."""
    venv = gym.make_vec("RollingDrive-v0", num_envs=3, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    for _ in range(5):
        venv.step(np.zeros((3, 3)))
    core = venv.unwrapped.core
    state = (core.steps.copy(), core.target.copy(), core.st.copy())
    rngs = [r.bit_generator.state for r in core.rngs]
    for bad in (
        [{"target": 1e-7}, {"target": "x"}, None],
        [{"target": 1e-7}, {"targte": 1}, None],
        {"target": 1.0},
    ):
        with pytest.raises(ValueError, match="options"):
            venv.reset(seed=5, options=bad)
        assert all(np.array_equal(x, y) for x, y in zip(state, (core.steps, core.target, core.st)))
        assert [r.bit_generator.state for r in core.rngs] == rngs, "reseeded before the check"


def test_sb3_vecenv_checks_options_before_seeding():
    v = RollingDriveVecEnv(2)
    v.seed(0)
    v.reset()
    rngs = [r.bit_generator.state for r in v.core.rngs]
    v.seed(5)
    v.set_options({"target": 1.0})
    with pytest.raises(ValueError, match=r"options\['target'\]"):
        v.reset()
    assert [r.bit_generator.state for r in v.core.rngs] == rngs, "reseeded before the check"


def test_sb3_set_attr_target_checked():
    """set_attr("target", x) takes reset's check, naming the attribute it sets (an integer
    beyond the float range raised a bare OverflowError)."""
    v = RollingDriveVecEnv(2)
    for bad in (1.0, float("nan"), 10**400):
        with pytest.raises(ValueError, match=r"^target must be a finite displacement"):
            v.set_attr("target", bad, indices=[0])
    v.set_attr("target", np.float32(2e-7), indices=[0])
    assert v.core.target[0] == np.float32(2e-7)


@pytest.mark.parametrize("bad", [None, True, 2.0, 0])
def test_num_envs_must_be_a_positive_integer(bad):
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
        BatchCore(bad)


def test_sb3_vecenv_render_mode_named():
    with pytest.raises(ValueError, match="render_mode must be None"):
        RollingDriveVecEnv(2, render_mode="rgb_array")


def test_gymnasium_vector_env_checks_the_action_shape_while_an_env_is_pending_autoreset():
    """A (3,) or (1, 3) action for 2 envs is refused on every step, also on the step where an
    env is pending autoreset (np.where broadcast it to both envs there)."""
    venv = gym.make_vec(
        "RollingDrive-v0", num_envs=2, episode_steps=2, vectorization_mode="vector_entry_point"
    )
    venv.reset(seed=0)
    for _ in range(2):
        venv.step(np.zeros((2, 3), np.float32))
    assert venv.unwrapped._autoreset.any(), "setup: an env must be pending autoreset"
    for bad in (np.full(3, 0.5, np.float32), np.full((1, 3), 0.5, np.float32)):
        with pytest.raises(ValueError, match=r"action must have shape \(2, 3\)"):
            venv.step(bad)


@pytest.mark.parametrize(
    "name,value,match",
    [
        ("steps", -5, r"steps must be an integer in \[0, 511\]"),
        ("steps", 2.5, "steps must be an integer"),
        ("steps", 512, r"steps must be an integer in \[0, 511\]"),
        ("rngs", 5, "rngs must be a numpy.random.Generator"),
        ("U", 0.0, "'U' is per-env physics state, read-only"),
        ("obs", 0.0, "'obs' is per-env physics state, read-only"),
    ],
)
def test_sb3_set_attr_checks_per_env_state(name, value, match):
    """Per-env state other than target was written unchecked (steps -5 accepted, rngs 5
    failed later at reset): checked values, or a refusal naming the attribute; nothing
    changes on a refusal."""
    v = RollingDriveVecEnv(2)
    v.reset()
    before = [np.copy(x) if isinstance(x, np.ndarray) else x for x in v.get_attr(name)]
    with pytest.raises((ValueError, AttributeError), match=match):
        v.set_attr(name, value, indices=[0])
    after = v.get_attr(name)
    assert all(a is b or np.array_equal(a, b) for a, b in zip(after, before)), f"{name} changed"
    v.set_attr("steps", 3, indices=[1])
    assert v.core.steps.tolist() == [0, 3]
    rng = np.random.default_rng(1)
    v.set_attr("rngs", rng, indices=[0])
    assert v.core.rngs[0] is rng


def test_sb3_env_method_reset_returns_obs_and_info_like_dummy_vec_env():
    """env_method("reset", indices=[i]) returns [(obs_i, info_i)] as SB3's DummyVecEnv does
    (it returned [None]), and takes the single env's seed and options."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    kw = dict(scene="resonant", episode_steps=6)
    a = RollingDriveVecEnv(3, **kw)
    b = DummyVecEnv([lambda: rolling_env.make(**kw) for _ in range(3)])
    for v in (a, b):
        v.seed(3)
        v.reset()
        v.step(np.full((3, 3), 0.3, np.float32))
    for args, kwargs in (((), {}), ((), {"seed": 7}), ((), {"options": {"target": 2e-7}})):
        ra = a.env_method("reset", *args, indices=[1, 2], **kwargs)
        rb = b.env_method("reset", *args, indices=[1, 2], **kwargs)
        assert len(ra) == len(rb) == 2
        for (oa, ia), (ob, ib) in zip(ra, rb):
            np.testing.assert_array_equal(oa, ob, err_msg=f"reset obs differ ({kwargs})")
            assert ia.keys() == ib.keys() and all(np.array_equal(ia[k], ib[k]) for k in ia), (
                f"reset infos differ ({kwargs}): {ia} vs {ib}"
            )
    sa = a.step(np.full((3, 3), 0.1, np.float32))
    sb = b.step(np.full((3, 3), 0.1, np.float32))
    np.testing.assert_array_equal(sa[0], sb[0], err_msg="steps after the resets differ")


def test_make_vec_needs_neither_sb3_nor_torch():
    """``gym.make_vec("RollingDrive-v0")`` steps without importing Stable-Baselines3 or torch
    (they cost 1.3 s and ~300 MiB); the SB3 adapter imports from rolling_env.env.sb3_vec."""
    code = (
        "import sys, numpy as np, gymnasium as gym, rolling_env; "
        "e = gym.make_vec('RollingDrive-v0', num_envs=2); e.reset(seed=0); "
        "e.step(np.zeros((2, 3), dtype=np.float32)); "
        "print(sorted(m for m in ('torch', 'stable_baselines3') if m in sys.modules)); "
        "from rolling_env.env.sb3_vec import RollingDriveVecEnv; "
        "print(RollingDriveVecEnv.__module__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    lines = out.stdout.split("\n")
    assert lines[0] == "[]", f"gym.make_vec imported {lines[0]}"
    assert lines[1] == "rolling_env.env.sb3_vec", f"the SB3 adapter is {lines[1]!r}"


def test_gymnasium_vector_env_needs_a_reset_before_step_like_sync():
    """As "sync" (gym.make's OrderEnforcing in each env): stepping an env that was never
    reset raises ResetNeeded, also after a masked first reset that left some envs out."""
    from gymnasium.error import ResetNeeded

    acts = np.zeros((3, 3), np.float32)
    for mode in ("sync", None):
        kw = {"vectorization_mode": mode} if mode else {}
        env = gym.make_vec("RollingDrive-v0", num_envs=3, **kw)
        with pytest.raises(ResetNeeded):
            env.step(acts)
        env.close()
    env = gym.make_vec("RollingDrive-v0", num_envs=3)
    env.reset(seed=0, options={"reset_mask": np.array([True, False, True])})
    with pytest.raises(ResetNeeded, match=r"\[1\]"):
        env.step(acts)
    env.reset(seed=0, options={"reset_mask": np.array([False, True, False])})
    obs, *_ = env.step(acts)  # every env has been reset once now
    assert obs.shape == (3, EK.N_OBS)


def test_a_batch_beyond_the_machine_memory_names_num_envs():
    """numpy's "Unable to allocate 7.9 PiB" named neither num_envs nor the scene keys that
    size an env's cells; checked before anything is allocated."""
    res = rolling_env.env.scenes.load_scene("default").resolution
    with pytest.raises(
        ValueError,
        match=r"^num_envs = 1000000000000 envs x .* MiB of cell "
        rf"state each \(resolution = {res}, grid_levels = 4, "
        r"stroke_roll",
    ):
        BatchCore(10**12)
