"""Threads of the batched env: the run-time choice between the serial and the threaded
kernel (``ThreadPolicy``, driven here by a fake clock: no timed asserts), bit-identical
transitions whichever kernel runs, the ``num_threads`` argument, and the training script's
choice of vector env."""

from __future__ import annotations

import json
import os
import time

import gymnasium as gym
import numba
import numpy as np
import pytest

import rolling_env  # noqa: F401  (registers RollingDrive-v0)
import rolling_env.env._envkernel as EK
from rolling_env.env.hostload import HostLoad
from rolling_env.env.sb3_vec import RollingDriveVecEnv
from rolling_env.env.threads import (
    PARALLEL_MIN_ENVS,
    ThreadPolicy,
    max_threads,
    thread_choices,
)
from rolling_env.env.vector import BatchCore
from tests.train_argv import tiny_ppo_argv

THREADS = min(2, max_threads())
two_threads = pytest.mark.skipif(max_threads() < 2, reason="numba runs one thread here")


class FakeClock:
    """A clock that only moves when told to."""

    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _drive(policy, clock, steps, kernel_s, gap_s=1e-4):
    """Run ``steps`` steps through ``policy.next``/``done`` on ``clock``: the kernel of choice
    i takes ``kernel_s(i, step)`` seconds, the caller ``gap_s`` between steps.  Returns the
    choice of each step and the clock time spent over always running the fastest choice."""
    picks, extra = [], 0.0
    for k in range(steps):
        i = policy.next()
        picks.append(i)
        t = kernel_s(i, k)
        extra += t - min(kernel_s(j, k) for j in range(len(policy.choices)))
        clock.t += t
        policy.done()
        clock.t += gap_s
    return picks, extra


@pytest.mark.parametrize("slow", [1.5, 3.0, 20.0])
def test_policy_settles_on_the_serial_kernel_when_threads_lose(slow):
    """Threaded steps ``slow`` times as long as serial ones: after the first probe the serial
    kernel runs, and the later probes of the threads cost about ``BUDGET`` of the time."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)
    cost = (1e-3, slow * 1e-3)
    picks, extra = _drive(p, clock, 5000, lambda i, k: cost[i])
    assert p.threads == 1 and p.current == 0, p.estimate
    assert p.estimate[1] > p.estimate[0]
    assert picks[-50:].count(1) <= ThreadPolicy.PROBE + 1
    total = 5000 * (1e-3 + 1e-4)
    first_probe = (ThreadPolicy.PROBE + 1) * (cost[1] - cost[0])
    assert extra <= 1.5 * ThreadPolicy.BUDGET * total + first_probe, (extra, total, p.probes)
    assert p.probes >= 2, "the threads must be re-measured now and then"


def test_policy_drops_a_far_slower_choice_after_one_timed_step():
    """A probe stops once its timed steps cost more over the current choice than the
    budget has bought since that choice last ran: threads 100x slower than serial run two
    steps (the switch and one timed step) in the first probe, not the full probe, and are
    probed again only after thousands of steps, within the budget."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)
    picks, extra = _drive(p, clock, 30_000, lambda i, k: (1e-4, 1e-2)[i], gap_s=0.0)
    runs = [k for k in range(1, len(picks)) if picks[k] == 1 and picks[k - 1] == 0]
    assert picks[runs[0] : runs[0] + 3] == [1, 1, 0], picks[runs[0] : runs[0] + 6]
    assert 2 <= len(runs) <= 4 and np.all(np.diff(runs) > 5000), runs
    assert extra <= 1.5 * ThreadPolicy.BUDGET * 30_000 * 1e-4 + 2e-2, extra
    assert p.threads == 1


def test_policy_undoes_a_lucky_probe_within_a_few_steps():
    """Threads whose probe happened to be fast (they had the core to themselves for a
    while) but whose steps then run 20x slower: the policy takes them, notices within a few
    steps (at the next renewal of its estimate) and goes back to the serial kernel."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)
    lucky = 200  # threaded steps at 0.5 ms: the first probe sees only these
    picks = []
    for _ in range(600):
        i = p.next()
        picks.append(i)
        clock.t += 1e-3 if i == 0 else (0.5e-3 if picks.count(1) <= lucky else 20e-3)
        p.done()
        clock.t += 1e-4
    assert p.switches >= 2 and p.threads == 1, (p.switches, p.estimate)
    # slow threaded steps run: at most until the estimate is next renewed
    assert 0 < picks.count(1) - lucky <= ThreadPolicy.RENEW, picks.count(1) - lucky


def test_policy_takes_the_threads_when_they_win():
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)
    picks, extra = _drive(p, clock, 3000, lambda i, k: (2e-3, 1e-3)[i])
    assert p.threads == 2 and p.switches >= 1
    assert picks[-1000:].count(0) < 50, picks[-1000:].count(0)
    assert extra <= 1.5 * ThreadPolicy.BUDGET * 3000 * 1.1e-3 + 2e-2, extra


def test_policy_follows_a_change_of_load():
    """Threads win for 1000 steps, then a busy host makes them 4x slower than serial: the
    policy goes back to the serial kernel within a few dozen steps (the guard), and back to
    the threads when the host is idle again."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)

    def cost(i, k):
        busy = 1000 <= k < 3000
        return (1e-3, 4e-3 if busy else 0.5e-3)[i]

    picks, _ = _drive(p, clock, 7000, cost)
    assert picks[900:1000].count(1) > 90, "threads win on the idle host"
    assert picks[1100:3000].count(0) > 1800, "serial on the busy host"
    back = next(k for k in range(1000, 3000) if picks[k : k + 20].count(0) == 20)
    assert back < 1050, f"took {back - 1000} steps to leave the slowed threads"
    # found again at the next probe, which the budget spaces by what the last one cost
    again = next(k for k in range(3000, 7000) if picks[k : k + 100].count(1) > 95)
    assert again < 3000 + 3000, again
    assert picks[-1000:].count(1) > 950, "threads again once the load is gone"


def test_policy_ignores_a_long_pause_between_steps():
    """A caller's pause (a learner's update, seconds long) between two steps is not taken
    for the kernel's cost: the times between steps count by their median."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)
    picks = []
    for k in range(3000):
        i = p.next()
        picks.append(i)
        clock.t += (1e-3, 0.5e-3)[i]
        p.done()
        clock.t += 5.0 if k % 256 == 255 else 1e-4
    assert p.threads == 2 and picks[-1000:].count(1) > 950, picks[-1000:].count(1)


def test_policy_counts_stalls_of_a_waiting_thread():
    """Threaded steps that are fast most of the time but now and then stall for a time slice
    (a worker thread waiting for a core) cost more on average than serial steps: the mean
    kernel time counts, so the serial kernel runs."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2), clock=clock)
    rng = np.random.default_rng(0)
    stall = rng.random(4000) < 0.3

    def cost(i, k):
        return 1e-3 if i == 0 else (12e-3 if stall[k] else 0.6e-3)

    picks, _ = _drive(p, clock, 4000, cost)
    assert p.threads == 1
    assert picks[1000:].count(1) < 0.03 * 3000, picks[1000:].count(1)


def test_thread_choices():
    assert thread_choices(PARALLEL_MIN_ENVS - 1, 16) == (1,)  # too few envs: serial only
    assert thread_choices(256, 1) == (1,)
    assert thread_choices(256, 2) == (1, 2)
    assert thread_choices(64, 16) == (1, 2, 4, 8, 16)
    assert thread_choices(6, 16) == (1, 2, 4, 6)  # never more threads than envs
    assert thread_choices(256, 12) == (1, 2, 4, 8, 12)


def _counted(fn, counter, key, clock=None, cost=0.0):
    def run(*args):
        counter[key] = counter.get(key, 0) + 1
        if clock is not None:
            clock.t += cost
        return fn(*args)

    return run


@two_threads
def test_batch_runs_the_serial_kernel_when_a_forced_calibration_says_threads_lose():
    """A real batch whose clock makes each threaded step take 5x a serial one: it ends on the
    serial kernel, and its transitions are those of the serial kernel alone."""
    core = BatchCore(8, max_episode_steps=30)
    ref = BatchCore(8, max_episode_steps=30, num_threads=1)
    p = core.thread_policy
    assert p.choices == (1, 2)
    assert isinstance(p.load, HostLoad), "the batch reads the host's load"
    p.load = None  # probe whatever the host's load of the moment
    clock = FakeClock()
    p.clock = clock
    ran = {}
    p._kernels = [
        _counted(p._kernels[0], ran, 1, clock, 1e-3),
        _counted(p._kernels[1], ran, 2, clock, 5e-3),
    ]
    for c in (core, ref):
        c.seed(4)
        c.reset()
    for acts in np.random.default_rng(5).uniform(-1, 1, (300, 8, 3)):
        o, r, t = core.step(acts)
        o2, r2, t2 = ref.step(acts)
        assert np.array_equal(o, o2) and np.array_equal(r, r2) and np.array_equal(t, t2)
        for c in (core, ref):
            if t.any():
                c.reset(t)
    # the probe of the threads stops after its switch step and one timed step: they
    # already cost more than a probe may
    assert core.threads == 1 and ran[2] >= 2 and ran[1] > 250, ran


@two_threads
@pytest.mark.parametrize("scene", ["default", "light_stiff", "heavy_inf_friction"])
def test_transitions_are_bit_identical_whichever_kernel_runs(scene):
    """Each step of the default batch on a randomly drawn kernel (serial, threaded): every
    observation, reward and truncation equals those of the batch always on the serial kernel
    and of the batch always on the threads, through episode ends and resets."""
    n = 9
    mixed = BatchCore(n, scene=scene, max_episode_steps=13)
    serial = BatchCore(n, scene=scene, max_episode_steps=13, num_threads=1)
    threaded = BatchCore(n, scene=scene, max_episode_steps=13, num_threads=THREADS)
    p = mixed.thread_policy
    draw = np.random.default_rng(2).integers(0, len(p.choices), 200)
    it = iter(draw)
    p.next = lambda: int(next(it))
    ran = {}
    p._kernels = [_counted(k, ran, i) for i, k in enumerate(p._kernels)]
    cores = (mixed, serial, threaded)
    for c in cores:
        c.seed(11)
        c.reset()
    for acts in np.random.default_rng(3).uniform(-1, 1, (200, n, 3)):
        out = [c.step(acts) for c in cores]
        for o, r, t in out[1:]:
            assert np.array_equal(out[0][0], o) and np.array_equal(out[0][1], r)
            assert np.array_equal(out[0][2], t)
        for c in cores:
            assert np.array_equal(c.st, mixed.st) and np.array_equal(c.cells, mixed.cells)
        if out[0][2].any():
            for c in cores:
                c.reset(out[0][2])
    assert ran.get(0, 0) > 50 and ran.get(1, 0) > 50, ran


@two_threads
def test_threads_leave_the_callers_numba_setting_as_it_was():
    """numba keeps its thread count per calling thread: a step on 2 threads sets it for the
    kernel only, and the default caps its choices at the caller's count when built; no
    environment variable (OMP_WAIT_POLICY, NUMBA_*) is set."""
    env_before = dict(os.environ)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        core = BatchCore(8, num_threads=2)
        core.reset()
        core.step(np.zeros((8, 3)))
        assert numba.get_num_threads() == 1, "the step changed the caller's thread count"
        assert BatchCore(8).thread_policy is None, "built with 1 thread: serial only"
        numba.set_num_threads(2)
        core = BatchCore(8)
        core.thread_policy.load = None  # probe whatever the host's load of the moment
        core.reset()
        for _ in range(40):
            core.step(np.zeros((8, 3)))
        assert numba.get_num_threads() == 2
        assert core.thread_policy.probes >= 1, "the threads were tried"
    finally:
        numba.set_num_threads(before)
    assert dict(os.environ) == env_before


BAD = [0, -1, 10**6, 1.5, 2.0, "2", True, np.float64(2.0), [2]]


@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize("make", ["core", "make_vec", "sb3"])
def test_num_threads_is_checked(make, bad):
    """A bad num_threads is one ValueError line naming the parameter and the range."""
    build = {
        "core": lambda: BatchCore(8, num_threads=bad),
        "make_vec": lambda: gym.make_vec("RollingDrive-v0", num_envs=8, num_threads=bad),
        "sb3": lambda: RollingDriveVecEnv(8, num_threads=bad),
    }[make]
    with pytest.raises(ValueError) as e:
        build()
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(
        f"num_threads must be None (chosen at run time) or an integer in [1, {max_threads()}]"
    ), msg
    assert msg.endswith(f"got {bad!r}"), msg


@pytest.mark.parametrize("k", [1, np.int64(1), THREADS, None])
def test_num_threads_accepts_none_and_counts(k):
    v = gym.make_vec("RollingDrive-v0", num_envs=8, num_threads=k)
    core = v.unwrapped.core
    assert core.num_threads == (None if k is None else int(k))
    if k is not None:
        assert core.threads == k and core.thread_policy is None
        assert (core._step_fn is EK.env_step_serial) == (k == 1)
    v.reset(seed=0)
    v.step(np.zeros((8, 3), dtype=np.float32))
    assert RollingDriveVecEnv(8, num_threads=k).core.num_threads == core.num_threads


# ----------------------------------------------------------------- agents.train
def test_make_vec_env_kinds_give_the_same_transitions():
    """The batched env and the DummyVecEnv of single envs that agents.train chooses between
    step identically (same seeds, rewards, episode ends and terminal observations)."""
    from agents.common import make_vec_env

    kw = {"max_episode_steps": 20}
    a = make_vec_env("default", 3, 5, kw, kind="batched")
    b = make_vec_env("default", 3, 5, kw, kind="dummy")
    assert np.array_equal(a.reset(), b.reset())
    for acts in np.random.default_rng(0).uniform(-1, 1, (45, 3, 3)).astype(np.float32):
        oa, ra, da, ia = a.step(acts)
        ob, rb, db, ib = b.step(acts)
        assert np.array_equal(oa, ob) and np.array_equal(ra, rb) and np.array_equal(da, db)
        for x, y in zip(ia, ib):
            assert ("terminal_observation" in x) == ("terminal_observation" in y)
            if "terminal_observation" in x:
                assert np.array_equal(x["terminal_observation"], y["terminal_observation"])
    with pytest.raises(ValueError, match="^kind must be 'batched' or 'dummy'"):
        make_vec_env("default", 1, 0, kind="subproc")


@pytest.mark.parametrize(
    "rates,want",
    [({"batched": 5e4, "dummy": 2e4}, "batched"), ({"batched": 1e4, "dummy": 2e4}, "dummy")],
)
def test_train_takes_the_faster_vector_env(rates, want):
    from agents.vec_choice import choose_vec_env

    seen = []

    def measure(scene, n_envs, env_kwargs, num_threads):
        seen.append((scene, n_envs, num_threads))
        return rates

    kind, record = choose_vec_env("auto", "default", 8, {}, None, measure=measure)
    assert kind == want and seen == [("default", 8, None)]
    assert record == {
        "kind": want,
        "chosen_by": "measured at start",
        "env_steps_per_s": {k: round(v) for k, v in rates.items()},
    }


@pytest.mark.parametrize("flag", ["batched", "dummy"])
def test_train_vec_env_flag_overrides_the_measurement(flag):
    from agents.vec_choice import choose_vec_env

    def measure(*a):
        raise AssertionError("measured despite --vec-env")

    assert choose_vec_env(flag, "default", 8, {}, None, measure=measure) == (
        flag,
        {"kind": flag, "chosen_by": "--vec-env"},
    )


def test_train_measurement_rates_both_kinds():
    from agents.vec_choice import measure_vec_envs

    rates = measure_vec_envs("default", 2, {}, None, seconds=0.1, rounds=1)
    assert set(rates) == {"batched", "dummy"} and all(v > 0 for v in rates.values()), rates


@pytest.mark.parametrize(
    "text,want", [("auto", None), ("1", 1), (str(max_threads()), max_threads())]
)
def test_train_num_threads_flag(text, want):
    from agents.train import build_parser

    args = build_parser().parse_args(["--algo", "ppo", "--num-threads", text])
    assert args.num_threads == want and args.vec_env == "auto"


@pytest.mark.parametrize("text", ["0", str(max_threads() + 1), "two", "1.5", ""])
def test_train_refuses_a_bad_num_threads(text, capsys):
    from agents.train import build_parser

    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(["--algo", "ppo", "--num-threads", text])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith(
        f"argument --num-threads: num-threads must be 'auto' or an integer in "
        f"[1, {max_threads()}], got {text!r}"
    ), err


def test_train_records_the_vector_env_in_meta(tmp_path):
    """--vec-env dummy trains on SB3's DummyVecEnv (no measurement) and meta.json says so,
    with the --num-threads setting."""
    from agents.train import main as train_main

    run = tmp_path / "run"
    argv = tiny_ppo_argv(
        *("--run-dir", str(run), "--vec-env", "dummy", "--num-threads", "1"), n_envs=2
    )
    assert train_main(argv) == 0
    meta = json.loads((run / "meta.json").read_text())
    assert meta["vec_env"] == {"kind": "dummy", "chosen_by": "--vec-env", "num_threads": 1}
    assert meta["env_steps"] >= 64


# ----------------------------------------------------------------- probes and the host's load
class _Load:
    """A host load reading ``room[0]`` spare cores; counts the steps observed."""

    def __init__(self, room):
        self.room, self.steps, self.pauses = room, 0, 0

    def observe(self, now, paused=False):
        self.steps += 1
        self.pauses += paused

    def spare(self, now):
        return self.room[0]


def test_policy_puts_off_probes_of_threads_while_the_cores_are_taken():
    """Other processes hold a core (``spare`` reports 0.9 of 2): the threads are not probed
    at all, the gated count says why; once the cores are free they are probed and, faster
    here, taken."""
    clock = FakeClock()
    room = [0.9]
    p = ThreadPolicy((1, 2), clock=clock, load=_Load(room))
    picks, _ = _drive(p, clock, 3000, lambda i, k: (1e-3, 0.6e-3)[i])
    assert picks.count(1) == 0 and p.probes == 0, (picks.count(1), p.probes)
    # put off by MIN_STEPS steps each time, not re-planned sooner
    assert abs(p.gated - 3000 / ThreadPolicy.MIN_STEPS) <= 2, p.gated
    room[0] = 1.9
    picks, _ = _drive(p, clock, 2000, lambda i, k: (1e-3, 0.6e-3)[i])
    assert p.threads == 2 and picks[-1000:].count(0) < 50, picks[-1000:].count(0)


def test_policy_probes_fewer_threads_whatever_the_load():
    """Threads won on the idle host; then the host fills (no spare core) and they run 4x
    slower: the serial kernel is still probed and taken (the gate holds back only probes of
    more threads)."""
    clock = FakeClock()
    room = [2.0]
    p = ThreadPolicy((1, 2), clock=clock, load=_Load(room))

    def cost(i, k):
        busy = k >= 1000
        room[0] = 0.2 if busy else 2.0
        return (1e-3, 4e-3 if busy else 0.5e-3)[i]

    picks, _ = _drive(p, clock, 3000, cost)
    assert picks[900:1000].count(1) > 90, "threads win on the idle host"
    assert picks[1100:].count(0) > 1890, picks[1100:].count(0)
    assert p.gated > 0


def test_policy_without_a_load_reading_probes_as_before():
    """A reading of None (unknown, not Linux): the same picks as without a load."""
    picks = []
    for load in (None, _Load([None])):
        clock = FakeClock()
        p = ThreadPolicy((1, 2), clock=clock, load=load)
        picks.append(_drive(p, clock, 2000, lambda i, k: (1e-3, 2e-3)[i])[0])
        assert p.gated == 0
    assert picks[0] == picks[1] and picks[0].count(1) > 0


def _stat(path, busy, idle, cpus=(0, 1)):
    """A /proc/stat with each CPU of ``cpus`` at ``busy`` ticks split over user, system and
    steal, and ``idle`` idle ticks, niced and guest time (neither counts: niced processes
    yield, guest time is part of user) at as many as idle; plus a CPU outside the set,
    always busy."""
    lines = [f"cpu  {busy * 9} 0 0 {idle * 9} 0 0 0 0 0 0"]
    for c in cpus:
        u, s = busy // 2, busy // 4
        lines.append(f"cpu{c} {u} {idle} {s} {idle} 7 0 0 {busy - u - s} {idle} {idle}")
    lines.append(f"cpu9 {busy * 100} 0 0 0 0 0 0 0 0 0")
    path.write_text("\n".join(lines + ["intr 1 2 3", "ctxt 5"]) + "\n")


def test_host_load_counts_the_other_processes_cores(tmp_path):
    """Windows of steps: over 1 s the set's two CPUs were busy 150 ticks (1.5 s at 100
    ticks/s) of which this process used 0.4 s: the others took 1.1 cores, 0.9 are spare; the
    CPU outside the set and the iowait column do not count.  A step sooner than
    ``MIN_WINDOW`` reads nothing; a pause drops the open window (what ran meanwhile is not
    counted)."""
    stat = tmp_path / "stat"
    t, own = [0.0], [0.0]
    _stat(stat, 1000, 5000)
    h = HostLoad(path=str(stat), cpu_time=lambda: own[0], cpus=(0, 1))
    h._hz = 100.0
    h.observe(t[0])  # opens the first window
    assert h.spare(t[0]) is None, "nothing measured yet"
    _stat(stat, 1075, 5025)  # each CPU: 75 more busy ticks
    t[0], own[0] = 1.0, 0.4
    h.observe(t[0])
    assert h.spare(t[0]) == pytest.approx(0.9, abs=1e-9), h.spare(t[0])
    _stat(stat, 2000, 9000)  # too soon: counters not read, the window stays open
    t[0] = 1.0 + 0.5 * HostLoad.MIN_WINDOW
    h.observe(t[0])
    assert h.spare(t[0]) == pytest.approx(0.9, abs=1e-9)
    _stat(stat, 1075, 5125)  # all idle since t = 1
    t[0], own[0] = 2.0, 0.4
    h.observe(t[0])
    assert h.spare(t[0]) == pytest.approx(2.0, abs=1e-9)
    _stat(stat, 1175, 5125)  # this process alone kept both busy: nothing taken by others
    t[0], own[0] = 3.0, 2.4
    h.observe(t[0])
    assert h.spare(t[0]) == pytest.approx(2.0, abs=1e-9)
    _stat(stat, 1375, 5125)  # others busy during the caller's pause: not counted
    t[0] = 5.0
    h.observe(t[0], paused=True)
    _stat(stat, 1385, 5215)  # then 0.1 of a core each over 1 s: 0.2 taken
    t[0] = 5.1
    h.observe(t[0])
    _stat(stat, 1395, 5305)
    t[0] = 6.1
    h.observe(t[0])
    assert h.spare(t[0]) == pytest.approx(1.8, abs=1e-9), h.spare(t[0])


def test_policy_gates_only_larger_thread_counts():
    """Choices (1, 2, 4) on a host with 1.9 cores spare: 2 threads are probed and, faster,
    taken; 4 threads (3.5 cores needed) are never probed; the serial kernel still is."""
    clock = FakeClock()
    p = ThreadPolicy((1, 2, 4), clock=clock, load=_Load([1.9]))
    picks, _ = _drive(p, clock, 4000, lambda i, k: (1e-3, 0.6e-3, 0.4e-3)[i])
    assert p.threads == 2, p.estimate
    assert picks.count(2) == 0 and p.gated > 0, (picks.count(2), p.gated)
    assert picks[1000:].count(0) > 0, "the serial kernel is still probed"


def test_host_load_reading_expires(tmp_path):
    """A reading older than ``LIFE`` seconds is no reading."""
    stat = tmp_path / "stat"
    t = [0.0]
    _stat(stat, 1000, 5000)
    h = HostLoad(path=str(stat), cpu_time=lambda: 0.0, cpus=(0, 1))
    h._hz = 100.0
    h.observe(t[0])
    _stat(stat, 1050, 5050)
    t[0] = 1.0
    h.observe(t[0])
    assert h.spare(t[0]) == pytest.approx(1.0, abs=1e-9)
    t[0] = 1.0 + HostLoad.LIFE + 0.01
    assert h.spare(t[0]) is None


def test_host_load_unreadable_counters_read_as_unknown(tmp_path):
    h = HostLoad(path=str(tmp_path / "missing"))
    h.observe(0.0)
    h.observe(1.0)
    assert h.spare(1.0) is None
    stat = tmp_path / "stat"
    _stat(stat, 10, 10, cpus=(0,))
    h = HostLoad(path=str(stat), cpus=(0, 1))
    h.observe(0.0)
    h.observe(1.0)
    assert h.spare(1.0) is None, "a CPU of the set missing"


def test_policy_tells_the_load_of_each_step_and_its_pauses():
    """Each step is told to the load reader, with whether a gap longer than ``LOAD_GAP``
    came before it (the first step counts as one), on the threads too (so that the reading
    is current when the load drives the policy off them)."""
    clock = FakeClock()
    load = _Load([2.0])
    p = ThreadPolicy((1, 2), clock=clock, load=load)
    for k in range(300):
        i = p.next()
        clock.t += (1e-3, 2e-3)[i]  # the threads lose: serial throughout
        p.done()
        clock.t += 5.0 if k % 100 == 99 else 1e-4
    assert p.threads == 1
    assert load.steps == 300 and load.pauses == 1 + 2, (load.steps, load.pauses)
    _drive(p, clock, 1000, lambda i, k: (1e-3, 0.5e-3)[i])
    assert p.threads == 2
    told = load.steps
    _drive(p, clock, 500, lambda i, k: (1e-3, 0.5e-3)[i])
    assert p.threads == 2 and load.steps == told + 500, load.steps - told


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="reads Linux's /proc/stat")
def test_host_load_sees_a_busy_process():
    """A busy child process on this host takes most of a core: fewer than ncpu - 0.5 spare
    (it may be scheduled on any core of the set; the host's other load only lowers it)."""
    import subprocess
    import sys

    h = HostLoad()
    h.observe(time.perf_counter())
    if h._off:
        pytest.skip("/proc/stat does not list this process's CPUs")
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        h.observe(time.perf_counter())
        time.sleep(0.6)
        h.observe(time.perf_counter())
        room = h.spare(time.perf_counter())
    finally:
        busy.kill()
        busy.wait()
    assert room is not None and room <= len(h.cpus) - 0.5, (room, h.cpus)
