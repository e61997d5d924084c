"""Benchmarks that print numbers, as ratios against references measured in the same run.

* kernel throughput per scene in cell updates per second (cells in contact x sub-steps / s),
  against a rough machine limit;
* single env steps/s through ``gym.make`` vs Gymnasium's Pendulum-v1, measured the same way;
* the naive plain-numpy spring row (rolling_env.naive) at equal working-point accuracy;
* scene specialisation: the scene's kernel vs the same kernel with every feature switched on;
* batched env (256 envs) vs the single env, serial and threaded kernel and the default
  (threads chosen at run time), over batch sizes, and through the Gymnasium and SB3 adapters;
  the SB3 training env vs a DummyVecEnv;
* threads on a busy host: the batched env's default against the serial kernel on an idle
  host, beside a competing busy process, with the Python thread's own work between steps,
  and both; the host's own parallelism (two processes side by side);
* start-up (warm and cold numba cache) and peak memory (1 env, 1024 batched envs).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

CPU_HZ_FALLBACK = 3.0e9  # when /proc/cpuinfo gives no clock
FP_PER_CYCLE = 4  # double-precision vector operations per cycle (2 add + 2 mul/FMA pipes)
STORES_PER_CYCLE = 2  # two store ports (AMD Zen 4/5, Intel since Ice Lake)
# doubles per vector operation: the inner-cell loops are vectorised (_kernel.layout._FM_INNER);
# Zen 4's pipes are 256 bits wide (it splits AVX-512 in two halves), so 4 doubles
SIMD_DOUBLES = 4
# the minimal update of one cell inside the contact per sub-step (build + commit, see
# _kernel.tick._tick): with friction the friction limit (a quadratic, 13 operations), clip and slope
# (4), content and sums (6), commit with clip, slip and sums (13), storing A, L and U;
# without friction a copy, the creep update and two sums, storing A and U
OPS_PER_CELL = {"finite_mu": 36, "infinite_mu": 6}
STORES_PER_CELL = {"finite_mu": 3, "infinite_mu": 2}


def core_hz() -> float:
    """Core clock /proc/cpuinfo reports (Linux; often the base clock: boost runs faster), else
    CPU_HZ_FALLBACK."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("cpu MHz"):
                    return float(line.split(":")[1]) * 1e6
    except (OSError, ValueError, IndexError):
        pass
    return CPU_HZ_FALLBACK


ROUNDS = 3  # rounds of interleaved timed passes; each entry's best pass counts


def _best_rates(passes: dict, rounds=ROUNDS) -> dict:
    """Best rate of each named timed pass (a function that runs once and returns its rate),
    the passes taken in turn for ``rounds`` rounds.  Interleaved so that the entries a ratio
    compares see the same stretch of the shared host's load: timed one after the other, a
    burst during one entry's passes skewed the ratio (a single env measured 35% slow gave the
    batched env 13.9x instead of 8-9x in one run)."""
    best = dict.fromkeys(passes, 0.0)
    for _ in range(rounds):
        for name, run_pass in passes.items():
            best[name] = max(best[name], run_pass())
    return best


def _interleaved_rates(runs: dict, total: int, segment: int) -> dict:
    """Env steps/s of each entry, the entries run in turn in segments of ``segment`` steps
    until each has made ``total``: every entry meets the same stretches of the host's load,
    and the rate counts all its steps (a choice made at run time pays for its probes).  On
    a shared host whose load changes within seconds, the best passes of whole rounds gave
    two entries running the same kernel rates 2x apart.  The order changes each round
    (``_orders``), and each segment is followed by an untimed pause (``SEGMENT_PAUSE``).
    ``runs[name](k)`` makes the next
    k steps and returns the env steps made."""
    spent = dict.fromkeys(runs, 0.0)
    made = dict.fromkeys(runs, 0)
    orders = _orders(runs)
    for r, start in enumerate(range(0, total, segment)):
        k = min(segment, total - start)
        for name in orders[r % len(orders)]:
            t = time.perf_counter()
            made[name] += runs[name](k)
            spent[name] += time.perf_counter() - t
            time.sleep(SEGMENT_PAUSE)
    return {name: made[name] / spent[name] for name in runs}


# untimed pause after each segment: OpenMP's worker threads spin for some milliseconds after
# a threaded step, and would slow the next entry's first steps (a neighbour that a user's
# single env does not have); the order of the entries changes each round as well
SEGMENT_PAUSE = 0.05


def _orders(names) -> list:
    """The orders in which ``_interleaved_rates`` takes the entries, round after round:
    every permutation in turn, so that each entry follows each other one equally often."""
    import itertools

    return list(itertools.permutations(names))


def _segment(n_envs: int) -> int:
    """Steps of one segment for ``_interleaved_rates``: about 16k env steps (0.1-0.3 s
    here), long beside the switch from one entry to the next."""
    return max(16, 16_384 // n_envs)


def _env_pass(env, n, seed=0):
    """Timed pass of a single env: n steps of pre-sampled actions (resetting at episode
    ends), after a warm-up; returns steps/s per call."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (n, 3)).astype(np.float32)
    env.reset(seed=seed)
    for a in acts[: min(1000, n)]:
        env.step(a)

    def run_pass():
        t = time.perf_counter()
        for a in acts:
            _, _, te, tr, _ = env.step(a)
            if te or tr:
                env.reset()
        return n / (time.perf_counter() - t)

    return run_pass


def env_vs_pendulum(n=50_000, scenes=None):
    import gymnasium as gym

    import rolling_env

    scenes = scenes or rolling_env.list_scenes()
    passes = {"Pendulum-v1": _env_pass(gym.make("Pendulum-v1"), n)}
    passes.update((sc, _env_pass(gym.make("RollingDrive-v0", scene=sc), n)) for sc in scenes)
    r = _best_rates(passes)
    pend = r["Pendulum-v1"]
    return [dict(scene=sc, steps_per_s=r[sc], pendulum=pend, ratio=r[sc] / pend) for sc in scenes]


def _core_pass(core, ticks, seed=0):
    """Timed pass of a BatchCore on random actions (truncated envs reset as they end), after a
    warm-up; returns (env steps/s, cell updates/s) per call."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (ticks, core.num_envs, 3))
    sc = core.scene
    N = sc.N_min + 0.5 * (acts[..., 0] + 1) * (sc.N_max - sc.N_min)
    d = (3 * N / (4 * sc.E_star * math.sqrt(sc.R))) ** (2 / 3)
    cells = float(np.sum(2 * np.sqrt(sc.R * d) / (core.a_max / sc.resolution) + 2))
    core.seed(seed)
    core.reset()
    for a in acts[:20]:
        core.step(a)

    def run_pass():
        t = time.perf_counter()
        for a in acts:
            _, _, tr = core.step(a)
            if np.count_nonzero(tr):  # a quarter of the time of tr.any() for 256 envs
                core.reset(tr)
        dt = time.perf_counter() - t
        return ticks * core.num_envs / dt, cells * sc.n_sub / dt

    return run_pass


def _core_runner(core, ticks, seed=0):
    """A BatchCore's steps in segments (for ``_interleaved_rates``): ``run(k)`` makes the next
    k ticks of ``ticks`` random actions taken in a cycle (truncated envs reset as they end),
    after a warm-up."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (ticks, core.num_envs, 3))
    core.seed(seed)
    core.reset()
    for a in acts[:20]:
        core.step(a)
    at = [0]

    def run(k):
        for _ in range(k):
            _, _, tr = core.step(acts[at[0]])
            if np.count_nonzero(tr):
                core.reset(tr)
            at[0] = (at[0] + 1) % ticks
        return k * core.num_envs

    return run


def _steps(run_pass):
    """The env steps/s of a ``_core_pass`` (for ``_best_rates``)."""
    return lambda: run_pass()[0]


def _vec_pass(step, n_envs, ticks, seed=0, between=None):
    """Timed pass of a vector env adapter (``step(actions)``), after a warm-up; returns
    aggregate env steps/s per call.  ``between``: work of the calling thread after each step
    (called with the step's result)."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (ticks, n_envs, 3)).astype(np.float32)
    for a in acts[:20]:
        step(a)

    def run_pass():
        t = time.perf_counter()
        if between is None:
            for a in acts:
                step(a)
        else:
            for a in acts:
                between(step(a))
        return ticks * n_envs / (time.perf_counter() - t)

    return run_pass


def _limit(finite_mu: bool) -> float:
    """Rough machine limit in cell updates/s: the core clock over the cycles one cell update
    needs at best, the larger of its FP operations / (FP_PER_CYCLE x SIMD_DOUBLES) and its
    stores / (STORES_PER_CYCLE x SIMD_DOUBLES)."""
    key = "finite_mu" if finite_mu else "infinite_mu"
    cycles = (
        max(OPS_PER_CELL[key] / FP_PER_CYCLE, STORES_PER_CELL[key] / STORES_PER_CYCLE)
        / SIMD_DOUBLES
    )
    return core_hz() / cycles


def kernel_throughput(ticks=20_000, scenes=None):
    import rolling_env

    from .vector import BatchCore

    rows = []
    for sc in scenes or rolling_env.list_scenes():
        core = BatchCore(64, scene=sc, num_threads=1)  # the serial kernel
        limit = _limit(math.isfinite(core.scene.mu))
        run_pass = _core_pass(core, max(ticks // 64, 50))
        steps, cells = max(run_pass() for _ in range(ROUNDS))
        rows.append(
            dict(
                scene=sc,
                cell_updates_per_s=cells,
                limit=limit,
                fraction=cells / limit,
                env_steps_per_s=steps,
            )
        )
    return rows


def asymptotic_cell_rate(finite_mu: bool, resolution=128, n_sub=32, ticks=40):
    """Cell updates/s of the kernel (``Drive.run``, energy ledger on) on a large contact rolling
    at constant creep, where per-tick work and the few edge cells no longer count: what the
    per-cell arithmetic reaches, against the same machine limit."""
    from .experiments import Geometry
    from .model import Drive, DriveParams

    geo = Geometry()
    a1 = geo.a1
    params = DriveParams(geo.R, geo.E_star, geo.G_star, mu=0.3 if finite_mu else math.inf, m=1e-3)
    drv = Drive(
        params, a_ref=a1, resolution=resolution, stroke=(-6 * a1, 6 * a1), a_max=a1, t_ref=geo.tau
    )
    u = 8 * a1 / (ticks * geo.tau / 10)  # the patch travels 8 a1 in the run
    k = ticks
    kw = dict(
        dt_tick=geo.tau / 10,
        n_sub=n_sub,
        omega_R=np.full(k, u),
        v=np.full(k, u * (1 - 1e-3)),
        d=np.full(k, a1 * a1 / geo.R),
    )
    best = math.inf
    for _ in range(3):
        drv.reset(c0=-4 * a1)
        t = time.perf_counter()
        drv.run(**kw)
        best = min(best, time.perf_counter() - t)
    cells = (2 * resolution + 2) * n_sub * k
    rate = cells / best
    return dict(cell_updates_per_s=rate, limit=_limit(finite_mu), fraction=rate / _limit(finite_mu))


def specialisation(ticks=300, scenes=None):
    """Scene kernel vs the same kernel with every feature on: friction (mu 1e30 where it is
    infinite), load (0.0 where there is none) and the impulse/energy ledger."""
    import rolling_env

    from . import _kernel as K
    from .vector import BatchCore

    rows = []
    for sc in scenes or rolling_env.list_scenes():
        spec = BatchCore(64, scene=sc, num_threads=1)  # both on the serial kernel
        full = BatchCore(64, scene=sc, num_threads=1)
        mu, mass, load, _ = full.features
        full.features = (1e30 if mu is None else mu, mass, 0.0 if load is None else load, True)
        if full.cells.shape[1] < K.work_rows(True):  # infinite friction: no friction rows
            full.cells = np.zeros((full.num_envs, K.work_rows(True), full.cells.shape[2]))
        r = _best_rates(
            {"spec": _steps(_core_pass(spec, ticks)), "full": _steps(_core_pass(full, ticks))}
        )
        r_spec, r_full = r["spec"], r["full"]
        rows.append(
            dict(scene=sc, specialised=r_spec, all_features=r_full, speedup=r_spec / r_full)
        )
    return rows


TOP_ROUNDS = 5  # rounds for the batched-vs-single table (the headline ratio)


def _whole_episodes(ticks: int, episode: int) -> int:
    """``ticks`` rounded up to whole episodes: a timed pass of a batched env then holds its
    resets at the rate training meets them (each env resets once per ``episode`` ticks), as
    the single env's pass of many episodes does.  A pass shorter than an episode holds all
    the envs' resets or none, and the best of several passes picks one without them (3% of
    the batched env's steps/s at 256 envs before its reset was vectorised)."""
    return episode * max(1, -(-ticks // episode))


BATCH_SIZES = (1, 2, 4, 6, 8, 16, 64, 256, 1024)  # the table of where prange pays


def batched(n_envs=256, ticks=200, single_steps=20_000, sizes=BATCH_SIZES):
    """Aggregate steps/s of the batched core, serial and threaded kernel (all threads) and
    the default (``num_threads=None``: chosen at run time), over batch sizes (where prange
    pays), and at ``n_envs`` against the single env (``gym.make``, default scene,
    ``single_steps`` per pass) measured in the same rounds: the threaded kernel on all threads
    and on one, the default, and the two adapters, Gymnasium's ``gym.make_vec`` (NEXT_STEP
    autoreset) and the SB3 ``VecEnv`` (same-step), both with their defaults."""
    from functools import partial

    import gymnasium as gym

    from .sb3_vec import RollingDriveVecEnv
    from .scenes import load_scene
    from .vector import BatchCore, _threaded_step, max_threads

    episode = load_scene().episode_steps  # the default scene's
    most = max_threads()

    def core(n, num_threads, step_fn=None):
        c = BatchCore(n, num_threads=num_threads)
        if step_fn is not None:
            c._step_fn = step_fn
        return _steps(_core_pass(c, _whole_episodes(max(ticks, 20_000 // n), episode)))

    def runs(n):
        t = _whole_episodes(max(ticks, 20_000 // n), episode)
        return {
            name: _core_runner(BatchCore(n, num_threads=k), t)
            for name, k in (("serial", 1), ("threaded", most), ("default", None))
        }, t

    sweep = []
    for n in sizes:
        r, t = runs(n)
        sweep.append(dict(num_envs=n, **_interleaved_rates(r, ROUNDS * t, _segment(n))))
    genv = gym.make_vec("RollingDrive-v0", num_envs=n_envs)
    genv.reset(seed=0)
    venv = RollingDriveVecEnv(n_envs)
    venv.seed(0)
    venv.reset()
    out = _best_rates(
        {
            "single": _env_pass(gym.make("RollingDrive-v0"), single_steps),
            "serial": core(n_envs, 1),
            "threaded": core(n_envs, most),
            # the prange kernel on one thread: separates what the threads give from what the
            # parallel kernel's different generated code gives
            "threaded_1": core(n_envs, 1, partial(_threaded_step, 1)),
            "default": core(n_envs, None),
            "gym_vector": _vec_pass(genv.step, n_envs, _whole_episodes(ticks, episode)),
            "sb3_vecenv": _vec_pass(venv.step, n_envs, _whole_episodes(ticks, episode)),
        },
        TOP_ROUNDS,
    )
    out.update(sweep=sweep, num_envs=n_envs, threads=most)
    return out


def sb3_training_env(sizes=(1, 8, 256), ticks=2000):
    """SB3 vector envs as the training scripts would build them: the batched
    ``RollingDriveVecEnv`` vs SB3's ``DummyVecEnv`` of single envs, both in ``VecMonitor``."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    import rolling_env

    from .sb3_vec import RollingDriveVecEnv
    from .scenes import load_scene

    episode = load_scene().episode_steps  # the default scene's
    rows = []
    for n in sizes:
        passes = {}
        for name, venv in (
            ("batched", RollingDriveVecEnv(n)),
            ("dummy", DummyVecEnv([lambda: rolling_env.make("default") for _ in range(n)])),
        ):
            venv = VecMonitor(venv)
            venv.seed(0)
            venv.reset()
            passes[name] = _vec_pass(venv.step, n, _whole_episodes(max(ticks // n, 200), episode))
        rows.append(dict(num_envs=n, **_best_rates(passes)))
    return rows


# ----------------------------------------------------------------- threads on a busy host
LOAD_CONDITIONS = ("idle", "busy", "work", "busy+work")
# the competing process: one core's worth of pure Python, until its parent is gone (a
# benchmark killed before it could stop it leaves no busy process behind)
BUSY_CODE = "import os\nparent = os.getppid()\nwhile os.getppid() == parent:\n    pass\n"


class _Competitor:
    """A busy process for the duration of a ``with`` block (``busy`` False: none): a Python
    loop that keeps one core busy, as another user's job would; killed at the end."""

    def __init__(self, busy: bool):
        self.busy = busy
        self.proc = None

    def __enter__(self):
        if self.busy:
            self.proc = subprocess.Popen([sys.executable, "-c", BUSY_CODE])
            time.sleep(0.3)  # running before the first timed pass
        return self

    def __exit__(self, *exc):
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
        return False


_LOAD_WORKER = """
import sys, time
import numpy as np
kind, n, ticks = {kind!r}, {n}, {ticks}
if kind in ("batched", "dummy"):  # the SB3 training envs
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor
    import rolling_env
    from rolling_env.sb3_vec import RollingDriveVecEnv
    venv = (RollingDriveVecEnv(n) if kind == "batched" else
            DummyVecEnv([lambda: rolling_env.make("default") for _ in range(n)]))
    env = VecMonitor(venv)
    env.seed(0)
    env.reset()
    core = getattr(venv, "core", None)
else:  # gym.make_vec with num_threads = kind
    import gymnasium as gym
    import rolling_env
    env = gym.make_vec("RollingDrive-v0", num_envs=n,
                       num_threads=None if kind == "None" else int(kind))
    env.reset(seed=0)
    core = env.unwrapped.core
acts = np.random.default_rng(0).uniform(-1, 1, (ticks, n, 3)).astype(np.float32)
h = np.empty((n, 64))
w = np.linspace(-1.0, 1.0, 64)
def layer(obs):  # a policy's layer: element-wise numpy, one thread
    np.multiply(obs[:, :1], w, out=h)
    np.tanh(h, out=h)
at = 0
def run(k, reps):
    global at
    t = time.perf_counter()
    for _ in range(k):
        obs = env.step(acts[at])[0]
        at = (at + 1) % ticks
        for _ in range(reps):
            layer(obs)
    return time.perf_counter() - t
def layer_seconds():
    obs = acts[0][:, :1].repeat(13, axis=1)
    best = 1.0
    for _ in range(20):
        t = time.perf_counter()
        layer(obs)
        best = min(best, time.perf_counter() - t)
    return best
run(40, 0)  # kernels loaded, the default's first choice made
print("ready", layer_seconds(), flush=True)
for line in sys.stdin:
    cmd = line.split()
    if not cmd or cmd[0] != "go":
        break
    print(run(int(cmd[1]), int(cmd[2])), core.threads if core is not None else 0, flush=True)
"""


class _Workers:
    """Envs each in its own process, as a training process would hold one (so that no env
    meets another's threads), stepped on command one at a time: ``go(name, k, reps)`` makes
    k steps, each followed by ``reps`` layers of a policy's numpy work, and returns the
    seconds they took and the thread count the env then steps on."""

    def __init__(self, kinds: dict, n_envs: int, ticks: int):
        self.procs = {}
        try:
            self.layer_seconds = {}
            # one at a time: a worker's first steps (the default's first probes) meet no
            # other worker's start-up, as a training process starting alone would
            for name, kind in kinds.items():
                code = _LOAD_WORKER.format(kind=kind, n=n_envs, ticks=ticks)
                p = self.procs[name] = subprocess.Popen(
                    [sys.executable, "-c", code],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    text=True,
                )
                word, *rest = p.stdout.readline().split() or ["failed"]
                if word != "ready":
                    raise RuntimeError(f"the benchmark worker {name!r} failed to start")
                self.layer_seconds[name] = float(rest[0])
        except BaseException:
            self.close()
            raise

    def go(self, name: str, k: int, reps: int = 0):
        p = self.procs[name]
        p.stdin.write(f"go {k} {reps}\n")
        p.stdin.flush()
        seconds, threads = p.stdout.readline().split()
        return float(seconds), int(threads)

    def rates(self, names, n_envs: int, total: int, segment: int, reps: int = 0) -> dict:
        """Env steps/s of each worker of ``names``, taken in turn in segments of ``segment``
        steps until each has made ``total`` (orders and pauses as ``_interleaved_rates``)."""
        spent = dict.fromkeys(names, 0.0)
        orders = _orders(names)
        for r, start in enumerate(range(0, total, segment)):
            k = min(segment, total - start)
            for name in orders[r % len(orders)]:
                spent[name] += self.go(name, k, reps)[0]
                time.sleep(SEGMENT_PAUSE)
        return {name: total * n_envs / spent[name] for name in names}

    def close(self):
        for p in self.procs.values():
            p.kill()
            p.wait()


def threads_under_load(
    n_envs=256, ticks=200, sb3_envs=8, sb3_ticks=2000, conditions=LOAD_CONDITIONS
):
    """``gym.make_vec("RollingDrive-v0", num_envs=n_envs)`` with its default threading
    (``num_threads=None``) against the same env on the serial kernel (``num_threads=1``) and
    on all threads, in each condition: ``idle`` (nothing else of ours running), ``busy`` (a
    competing busy process, ``BUSY_CODE``), ``work`` (the env's thread does a policy's
    worth of numpy between steps, about as long as a serial step) and ``busy+work``.  Each
    env lives in its own process (``_Workers``) through all conditions in turn, so the
    default must follow the load as it changes; the three are taken in turn in short
    segments, so that they meet the same stretches of the host's load.  In the conditions
    without work, also the SB3 training env at ``sb3_envs`` envs: the batched
    ``RollingDriveVecEnv`` (default threading) vs a ``DummyVecEnv`` of single envs, both in
    ``VecMonitor``."""
    from .scenes import load_scene
    from .vector import max_threads

    episode = load_scene().episode_steps  # the default scene's
    most = max_threads()
    ticks = _whole_episodes(ticks, episode)
    sb3_ticks = _whole_episodes(max(sb3_ticks // sb3_envs, 200), episode)
    envs = _Workers({"serial": "1", "threads": str(most), "default": "None"}, n_envs, ticks)
    try:
        sb3 = _Workers({"batched": "batched", "dummy": "dummy"}, sb3_envs, sb3_ticks)
    except BaseException:
        envs.close()
        raise
    try:
        seg = _LOAD_SEGMENT * 256 // n_envs or 1
        step_s = envs.go("serial", 4 * seg)[0] / (4 * seg)
        reps = max(1, round(step_s / envs.layer_seconds["serial"]))
        rows = []
        for cond in conditions:
            load = _load_average()
            with _Competitor("busy" in cond):
                r = envs.rates(
                    ("serial", "threads", "default"),
                    n_envs,
                    TOP_ROUNDS * ticks,
                    seg,
                    reps if "work" in cond else 0,
                )
                row = dict(
                    condition=cond, **r, load_average=load, default_threads=envs.go("default", 1)[1]
                )
                if "work" not in cond:
                    s3 = sb3.rates(
                        ("batched", "dummy"),
                        sb3_envs,
                        TOP_ROUNDS * sb3_ticks,
                        max(64, 8192 // sb3_envs),
                    )
                    row.update(sb3_batched=s3["batched"], sb3_dummy=s3["dummy"])
            rows.append(row)
    finally:
        envs.close()
        sb3.close()
    return dict(
        num_envs=n_envs,
        threads=most,
        sb3_envs=sb3_envs,
        segment=seg,
        work_seconds=reps * envs.layer_seconds["serial"],
        serial_step_seconds=step_s,
        rows=rows,
    )


# steps of 256 envs in one segment of the load table (more for fewer envs): long enough
# (0.2-0.4 s) that the default's reading of the host's load spans its own steps
_LOAD_SEGMENT = 128


def _load_average() -> float:
    """The host's 1-minute load average (this process included; nan where the OS does not
    say): what else was running when a condition started."""
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return math.nan


_WORKER = """
import sys, time
import numpy as np
from rolling_env.vector import BatchCore
n, ticks = {n}, {ticks}
core = BatchCore(n, num_threads=1)
core.seed(0)
core.reset()
acts = np.random.default_rng(0).uniform(-1, 1, (ticks, n, 3))
def run():
    t = time.perf_counter()
    for a in acts:
        _, _, tr = core.step(a)
        if np.count_nonzero(tr):
            core.reset(tr)
    return ticks * n / (time.perf_counter() - t)
run()
print("ready", flush=True)
for line in sys.stdin:
    if line.strip() != "go":
        break
    print(run(), flush=True)
"""


def host_parallelism(n_envs=256, ticks=512, rounds=TOP_ROUNDS):
    """What the host's second core gives two independent processes: two worker processes
    step the serial kernel (``n_envs`` envs, ``ticks`` ticks a pass); in each round one of
    them (each in turn) runs a pass alone, then both at once.  Returns the best rate alone,
    the best sum of the pair and their ratio (2 on an idle 2-core host; what threads can
    reach at most)."""
    code = _WORKER.format(n=n_envs, ticks=ticks)
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        for _ in range(2)
    ]
    try:
        for p in procs:
            if p.stdout.readline().strip() != "ready":
                raise RuntimeError("a benchmark worker process failed to start")

        def go(ps):
            for p in ps:
                p.stdin.write("go\n")
                p.stdin.flush()
            return [float(p.stdout.readline()) for p in ps]

        alone = pair = 0.0
        for r in range(rounds):  # each worker alone in turn, then both
            alone = max(alone, go(procs[r % 2 : r % 2 + 1])[0])
            time.sleep(SEGMENT_PAUSE)
            pair = max(pair, sum(go(procs)))
            time.sleep(SEGMENT_PAUSE)
    finally:
        for p in procs:
            p.kill()
            p.wait()
    return dict(num_envs=n_envs, alone=alone, pair=pair, ratio=pair / alone)


_NAIVE_BURST = 4  # back-to-back calls of a kernel in one pass of the naive comparison
_NAIVE_ROUNDS = 10  # rounds of the two kernels in turn: 40 back-to-back timings each


def _timed(fn, calls=1):
    """A timed pass of ``calls`` back-to-back calls of ``fn``: returns the best calls/s of them
    (for ``_best_rates``; the first call of a pass may find cold caches, the others not)."""

    def run_pass():
        best = 0.0
        for _ in range(calls):
            t = time.perf_counter()
            fn()
            best = max(best, 1.0 / (time.perf_counter() - t))
        return best

    return run_pass


def naive_equal_accuracy():
    """Working point (0.7, 0.1, 2.5): ours at 8 springs/a1 (worst-case error 6.6e-3 over grid
    alignments) vs the naive row at 64 springs/a1 (1.1e-2): ours is the more accurate."""
    from . import analytic, naive
    from . import experiments as ex

    case = (0.7, 0.1, 2.5)
    ref = analytic.eq32(*case)

    def ours():
        return ex.working_point(*case, resolution=8)

    def plain():
        return naive.working_point(*case, 64)

    r, v = ours(), plain()  # warm-up (numba cache load) and the results
    # the same number of back-to-back timings for both (best counts), taken in rounds in turn:
    # 40 of ours in a row span only 9 ms, and twice in eight runs on 2026-11-24 a burst of the
    # shared host's load covered them all (ours 0.32 ms instead of 0.21, 85-87x)
    warm = _best_rates(
        {"ours": _timed(ours, _NAIVE_BURST), "naive": _timed(plain, _NAIVE_BURST)}, _NAIVE_ROUNDS
    )
    t_ours, t_naive = 1.0 / warm["ours"], 1.0 / warm["naive"]
    # each call right after the other kernel's, which has evicted its code and data from the
    # caches (a user who computes one working point among other work sees this time)
    cold = _best_rates({"ours": _timed(ours), "naive": _timed(plain)}, _NAIVE_ROUNDS)
    c_ours, c_naive = 1.0 / cold["ours"], 1.0 / cold["naive"]
    return dict(
        ours_seconds=t_ours,
        ours_error=abs(r["simulated"] - ref) / ref,
        naive_seconds=t_naive,
        naive_error=abs(v - ref) / ref,
        speedup=t_naive / t_ours,
        ours_cold_seconds=c_ours,
        naive_cold_seconds=c_naive,
        speedup_cold=c_naive / c_ours,
    )


_STARTUP = (
    "import time; t = time.perf_counter(); import gymnasium as gym, rolling_env; "
    "e = gym.make('RollingDrive-v0'); e.reset(seed=0); e.step(e.action_space.sample()); "
    "print(time.perf_counter() - t)"
)
# peak RSS from /proc/self/status (VmHWM, kB): on Linux getrusage's ru_maxrss survives fork +
# exec, so in a subprocess it reported the benchmark process's own peak (389 MiB with torch
# loaded) until 2026-11-24; ru_maxrss (kB on Linux) only where there is no /proc
_PEAK = """
def peak():
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        import resource
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
"""
_MEMORY = (
    _PEAK
    + """
import numpy as np, gymnasium as gym, rolling_env
base = peak()
n = {n}
if n == 1:
    x = gym.make("RollingDrive-v0"); x.reset(seed=0); x.step(x.action_space.sample())
    d = x.unwrapped.drive
    arrs = [d.cells, d.st]
else:
    x = gym.make_vec("RollingDrive-v0", num_envs=n); x.reset(seed=0)
    x.step(np.zeros((n, 3), dtype=np.float32))
    c = x.core
    arrs = [c.cells, c.st, c.p, c.obs, c.out, c.extra]
print(base, peak(), sum(a.nbytes for a in arrs))
"""
)


def startup_and_memory():
    env = dict(os.environ)
    warm = float(
        subprocess.run(
            [sys.executable, "-c", _STARTUP], capture_output=True, text=True, check=True, env=env
        ).stdout
    )
    with tempfile.TemporaryDirectory() as d:
        cold_env = dict(env, NUMBA_CACHE_DIR=d)
        cold = float(
            subprocess.run(
                [sys.executable, "-c", _STARTUP],
                capture_output=True,
                text=True,
                check=True,
                env=cold_env,
            ).stdout
        )
    mem = {}
    for n in (1, 1024):
        base, peak, state = map(
            int,
            subprocess.run(
                [sys.executable, "-c", _MEMORY.format(n=n)],
                capture_output=True,
                text=True,
                check=True,
                env=env,
            ).stdout.split(),
        )
        mem[n] = dict(
            peak_mib=peak / 1024, above_imports_mib=(peak - base) / 1024, state_mib=state / 2**20
        )
    return dict(warm_seconds=warm, cold_seconds=cold, memory=mem)


def run(quick=False) -> dict:
    scenes = ["default", "heavy_inf_friction"] if quick else None
    res = {
        "env": env_vs_pendulum(10_000 if quick else 20_000, scenes),
        "kernel": kernel_throughput(2_000 if quick else 20_000, scenes),
        "asymptotic": {
            "finite_mu": asymptotic_cell_rate(True),
            "infinite_mu": asymptotic_cell_rate(False),
        },
        "specialisation": specialisation(50 if quick else 300, scenes),
    }
    res["batched"] = batched(
        64 if quick else 256,
        50 if quick else 200,
        10_000 if quick else 20_000,
        (1, 64) if quick else BATCH_SIZES,
    )
    res["sb3"] = sb3_training_env((1, 8) if quick else (1, 8, 256))
    res["load"] = threads_under_load(64 if quick else 256)
    res["host"] = host_parallelism(64 if quick else 256)
    res["naive"] = naive_equal_accuracy()
    res["startup"] = startup_and_memory()
    return res


def report(res) -> str:
    L = [
        "# Benchmarks",
        "",
        "Generated by `rolling-drive bench` on this project's 2-core CPU machine (no GPU); "
        "every ratio compares numbers measured in the same run, and the entries a ratio "
        f"compares were timed in turn (best pass of {ROUNDS} interleaved rounds, "
        f"{TOP_ROUNDS} for the batched-vs-single table), so that a burst of the shared "
        "host's load hits them alike.",
        "",
        "## Single env through gym.make (pre-sampled actions) vs Pendulum-v1",
        "",
        "| scene | steps/s | Pendulum-v1 steps/s | ratio (target >= 1, at least 0.25) |",
        "|---|---|---|---|",
    ]
    L += [
        f"| {r['scene']} | {r['steps_per_s']:,.0f} | {r['pendulum']:,.0f} | {r['ratio']:.2f} |"
        for r in res["env"]
    ]
    L += [
        "",
        "## Kernel throughput (64 envs, serial kernel, random actions)",
        "",
        f"Machine limit estimate: the core clock /proc/cpuinfo reports ({core_hz() / 1e9:.2f} "
        "GHz; a boost clock would raise the limit and lower every fraction below) over the "
        "cycles of the minimal update of one cell inside the contact, the larger of its "
        f"floating-point operations / {FP_PER_CYCLE} per cycle (two add and two mul pipes) "
        f"and its stores / {STORES_PER_CYCLE} per cycle, each on vectors of {SIMD_DOUBLES} "
        "doubles (the inner-cell loops are vectorised; latency of the sums ignored): "
        f"{OPS_PER_CELL['finite_mu']} operations and {STORES_PER_CELL['finite_mu']} stores "
        f"with friction = {_limit(True) / 1e6:.0f} M/s, {OPS_PER_CELL['infinite_mu']} "
        f"operations and {STORES_PER_CELL['infinite_mu']} stores without = "
        f"{_limit(False) / 1e6:.0f} M/s per core.  Cells counted: 2a/dx + 2 per sub-step, "
        "from the commanded force.",
        "",
        "| scene | cell updates/s | fraction of limit | env steps/s |",
        "|---|---|---|---|",
    ]
    L += [
        f"| {r['scene']} | {r['cell_updates_per_s'] / 1e6:.1f} M | {r['fraction']:.2f} | "
        f"{r['env_steps_per_s']:,.0f} |"
        for r in res["kernel"]
    ]
    asy = res.get("asymptotic")
    if asy:
        L += [
            "",
            "The physics kernel through `Drive.run` (energy ledger on: a little more work "
            "than the env's) on a large contact (256 cells, 32 sub-steps per tick, rolling at "
            "constant creep), where the per-tick work and "
            "the few edge cells no longer count: "
            f"{asy['finite_mu']['cell_updates_per_s'] / 1e6:.0f} M/s with friction "
            f"({asy['finite_mu']['fraction']:.2f} of the limit), "
            f"{asy['infinite_mu']['cell_updates_per_s'] / 1e6:.0f} M/s without "
            f"({asy['infinite_mu']['fraction']:.2f}).  At 16 cells per radius the scenes' contacts "
            "span at most 34 cells, so there the per-tick work (action mapping, load change, "
            "observation) and the edge cells, integrated one by one exactly through their "
            "entry and exit, take the rest.",
        ]
    L += [
        "",
        "## Scene specialisation (env steps/s, 64 envs, serial)",
        "",
        "Every feature on: friction (mu = 1e30 where the scene has none), the load term "
        "(F_ext = 0.0 where it has none) and the impulse/energy ledger, which the env never "
        "needs.",
        "",
        "| scene | specialised kernel | every feature on | speed-up |",
        "|---|---|---|---|",
    ]
    L += [
        f"| {r['scene']} | {r['specialised']:,.0f} | {r['all_features']:,.0f} | "
        f"{r['speedup']:.2f}x |"
        for r in res["specialisation"]
    ]
    b = res["batched"]
    n = b["num_envs"]
    L += [
        "",
        f"## Batched env vs single env (default scene, {n} envs, random actions)",
        "",
        "Every timed pass spans whole episodes, so each holds the resets at the rate "
        "training meets them: the batched passes reset every env once per episode, the "
        "single env's pass of many episodes its own.",
        "",
        "| | aggregate env steps/s | vs single env (target >= 8x) |",
        "|---|---|---|",
        f"| single env (gym.make) | {b['single']:,.0f} | 1.00x |",
        f"| batched core, serial kernel | {b['serial']:,.0f} | {b['serial'] / b['single']:.2f}x |",
        f"| batched core, threaded kernel (prange) on 1 thread | {b['threaded_1']:,.0f} | "
        f"{b['threaded_1'] / b['single']:.2f}x |",
        f"| batched core, threaded kernel (prange, {b['threads']} threads) | "
        f"{b['threaded']:,.0f} | {b['threaded'] / b['single']:.2f}x |",
        f"| batched core, default (threads chosen at run time) | {b['default']:,.0f} | "
        f"{b['default'] / b['single']:.2f}x |",
        f'| `gym.make_vec("RollingDrive-v0", num_envs={n})` | {b["gym_vector"]:,.0f} | '
        f"{b['gym_vector'] / b['single']:.2f}x |",
        f"| SB3 `RollingDriveVecEnv({n})` | {b['sb3_vecenv']:,.0f} | "
        f"{b['sb3_vecenv'] / b['single']:.2f}x |",
        "",
        "Where prange pays (batched core, aggregate env steps/s; the default picks the "
        "serial or the threaded kernel step by step from measured step times; the three "
        f"taken in turn in segments of about 16k env steps until each has made {ROUNDS} "
        "passes' worth, all steps over all their time):",
        "",
        "| envs | serial kernel | threaded kernel | threaded / serial | default | "
        "default / serial |",
        "|---|---|---|---|---|---|",
    ]
    L += [
        f"| {r['num_envs']} | {r['serial']:,.0f} | {r['threaded']:,.0f} | "
        f"{r['threaded'] / r['serial']:.2f} | {r['default']:,.0f} | "
        f"{r['default'] / r['serial']:.2f} |"
        for r in b["sweep"]
    ]
    L += [
        "",
        f"By default the batched env measures both kernels from {_parallel_min()} envs on "
        f"(below, the serial kernel only).  At "
        f"{n} envs the threads give {b['threaded'] / b['threaded_1']:.2f}x over the same "
        f"kernel on one thread; the rest of the threaded / serial ratio "
        f"({b['threaded_1'] / b['serial']:.2f}x) is the prange kernel's different generated "
        "code.",
    ]
    L += ["", *_ratio_bound(b)]
    if res.get("sb3"):
        L += [
            "",
            "## Training env (SB3, default scene, both in VecMonitor, passes of whole episodes)",
            "",
            "| envs | RollingDriveVecEnv (batched) | DummyVecEnv of single envs | ratio |",
            "|---|---|---|---|",
        ]
        L += [
            f"| {r['num_envs']} | {r['batched']:,.0f} | {r['dummy']:,.0f} | "
            f"{r['batched'] / r['dummy']:.1f}x |"
            for r in res["sb3"]
        ]
    if res.get("load"):
        L += ["", *_load_section(res["load"], res.get("host"), res["batched"])]
    n = res["naive"]
    if n:
        L += [
            "",
            "## Naive plain-numpy spring row at equal accuracy (working point 0.7, 0.1, 2.5)",
            "",
            "| kernel | resolution | rel. error vs Eq. 32 | seconds, back to back | "
            "seconds, after the other kernel |",
            "|---|---|---|---|---|",
            f"| ours | 8 springs/a1 | {n['ours_error']:.1e} | {n['ours_seconds']:.2e} | "
            f"{n['ours_cold_seconds']:.2e} |",
            f"| naive (rolling_env.naive) | 64 springs/a1 | {n['naive_error']:.1e} | "
            f"{n['naive_seconds']:.2e} | {n['naive_cold_seconds']:.2e} |",
            "",
            f"Speed-up at (better than) equal accuracy: {n['speedup']:.0f}x with each kernel "
            f"called back to back (best of {_NAIVE_BURST * _NAIVE_ROUNDS} each, in "
            f"{_NAIVE_ROUNDS} rounds of {_NAIVE_BURST} calls taken in turn; target >= 100x).  "
            f"Each call right after the other kernel's (best of {_NAIVE_ROUNDS} rounds), when "
            f"ours finds its code and data evicted from the caches: {n['speedup_cold']:.0f}x "
            f"(a {n['ours_seconds'] * 1e3:.2f} ms call pays for the refill; the naive row's "
            f"{n['naive_seconds'] * 1e3:.0f} ms hardly notice it).",
        ]
    s = res["startup"]
    L += [
        "",
        "## Start-up and memory",
        "",
        f"- import + gym.make + first step, warm numba cache: {s['warm_seconds']:.2f} s "
        "(target < 3 s)",
        f"- the same with an empty numba cache (cold, compiles): {s['cold_seconds']:.1f} s",
        f"- peak RSS of the process, one env (`gym.make`, one step): "
        f"{s['memory'][1]['peak_mib']:.0f} MiB, of which "
        f"{s['memory'][1]['peak_mib'] - s['memory'][1]['above_imports_mib']:.0f} MiB after "
        f"importing numpy, Gymnasium and rolling_env and "
        f"{s['memory'][1]['above_imports_mib']:.0f} MiB for making and stepping the env "
        f"(numba and LLVM, loaded with the first kernel; state arrays "
        f"{s['memory'][1]['state_mib']:.3f} MiB)",
        f"- peak RSS, batched env with 1024 envs (`gym.make_vec`, one step): "
        f"{s['memory'][1024]['peak_mib']:.0f} MiB ({s['memory'][1024]['above_imports_mib']:.0f}"
        f" MiB above the imports; state arrays {s['memory'][1024]['state_mib']:.1f} MiB)",
    ]
    return "\n".join(L) + "\n"


def ratio_bound(single, serial, one_thread, threads, target=10.0, efficiency=1.0) -> dict:
    """What batching can give at most, from rates measured in one run (env steps/s).

    The single env's step (``1/single``) is the physics tick, which costs what one env-step
    of the batched serial kernel costs (``1/serial``; the single env runs that kernel with a
    batch of one), plus a Python layer (gym.make's wrappers, the action check, the info dict,
    the kernel dispatch) that batching removes.  With ``threads`` threads scaling perfectly the
    batched env steps at ``threads * one_thread``, so the ratio is at most
    ``threads * one_thread / single``.  At a measured fraction ``efficiency`` of that rate, a
    physics tick ``f`` times faster (it speeds up both envs) makes the ratio reach ``target``
    at ``f = (target / (threads * one_thread * efficiency) - 1 / serial) / (1 / single -
    1 / serial)`` (1 or less: within reach now; ``efficiency`` = 1: perfect scaling)."""
    x, y, y1 = 1.0 / single, 1.0 / serial, 1.0 / one_thread
    need = (target * y1 / (threads * efficiency) - y) / (x - y) if x > y else math.inf
    return dict(
        step_us=1e6 * x,
        physics_us=1e6 * y,
        python_us=1e6 * (x - y),
        bound=threads * x / y1,
        speedup_needed=need,
        target=target,
    )


def _ratio_bound(b) -> list:
    one = max(b["serial"], b["threaded_1"])
    r = ratio_bound(b["single"], b["serial"], one, b["threads"])
    got = b["threaded"] / b["single"]
    eff = got / r["bound"]
    r_eff = ratio_bound(b["single"], b["serial"], one, b["threads"], efficiency=eff)
    f, f_eff = r["speedup_needed"], r_eff["speedup_needed"]
    return [
        "Where the single env's time goes, and what batching can give at most (same run): "
        f"its step takes {r['step_us']:.2f} us, of which {r['physics_us']:.2f} us is the "
        "physics tick (one env-step of the batched serial kernel, which the single env runs "
        f"with a batch of one) and {r['python_us']:.2f} us the Python layer (gym.make's "
        "wrappers, action check, info dict, kernel dispatch) that batching removes.  With "
        f"{b['threads']} threads scaling perfectly on the faster one-thread kernel "
        f"({1e6 / one:.2f} us per env-step), batching reaches at most {r['bound']:.2f}x; "
        f"measured {got:.2f}x ({eff:.0%} of that bound).  "
        + (
            f"{r['target']:.0f}x is reached."
            if got >= r["target"]
            else f"At that efficiency {r['target']:.0f}x needs a physics tick {f_eff:.2f}x as "
            "fast at the same accuracy (a faster tick also speeds up the single env); with "
            "perfect scaling it would need "
            + (f"{f:.2f}x." if f > 1.0 else "none (the bound is above it).")
        )
    ]


def _load_section(ld, host, b) -> list:
    """The report's section on threads under load (``threads_under_load``,
    ``host_parallelism`` and the idle gains of ``batched``'s sweep)."""
    n, k = ld["num_envs"], ld["threads"]
    names = {
        "idle": "idle (nothing else of ours running)",
        "busy": "a competing busy process (a pure-Python loop on one core)",
        "work": "the calling thread's own work between steps",
        "busy+work": "both",
    }
    L = [
        f"## Threads on a busy host (`gym.make_vec`, {n} envs, default scene)",
        "",
        "The same three envs in every condition, each in its own process (as a training "
        "process would hold it), taken in turn (every order in turn, a pause after each) in "
        "segments "
        f"of {ld['segment']} steps until each has made {TOP_ROUNDS} episodes (rates: all "
        "steps over all their time, so each env meets the same stretches of the host's load "
        "and the default pays for its probes): the serial kernel (`num_threads=1`), "
        f"the threaded kernel on {k} threads (`num_threads={k}`) and the default "
        "(`num_threads=None`), which picks between them step by step from measured step "
        "times and must follow each change of load.  The work between steps is a policy's "
        f"worth of element-wise numpy, {ld['work_seconds'] * 1e3:.2f} ms a step (about a "
        f"serial step, {ld['serial_step_seconds'] * 1e3:.2f} ms, when measured).",
        "",
        "| condition | serial kernel | threaded kernel | default | default / serial | "
        "threaded / serial | default ended on | load average |",
        "|---|---|---|---|---|---|---|---|",
    ]
    L += [
        f"| {names.get(r['condition'], r['condition'])} | {r['serial']:,.0f} | "
        f"{r['threads']:,.0f} | {r['default']:,.0f} | {r['default'] / r['serial']:.2f} | "
        f"{r['threads'] / r['serial']:.2f} | "
        + ("the serial kernel" if r["default_threads"] == 1 else f"{r['default_threads']} threads")
        + f" | {r.get('load_average', math.nan):.1f} |"
        for r in ld["rows"]
    ]
    L += [
        "",
        "Load average: the host's 1-minute load average when the condition started, "
        "this benchmark included (other users' work on a shared host shows here).",
    ]
    sb = [r for r in ld["rows"] if "sb3_batched" in r]
    if sb:
        L += [
            "",
            f"The SB3 training env at {ld['sb3_envs']} envs (both in VecMonitor, taken "
            "in turn in the same way; `agents.train` measures the two at start and trains "
            "on the faster):",
            "",
            "| condition | RollingDriveVecEnv (default threading) | DummyVecEnv of single "
            "envs | ratio |",
            "|---|---|---|---|",
        ]
        L += [
            f"| {names.get(r['condition'], r['condition'])} | {r['sb3_batched']:,.0f} | "
            f"{r['sb3_dummy']:,.0f} | {r['sb3_batched'] / r['sb3_dummy']:.2f}x |"
            for r in sb
        ]
    if host:
        gains = ", ".join(
            f"{r['threaded'] / r['serial']:.2f}x at {r['num_envs']} envs"
            for r in b["sweep"]
            if r["num_envs"] in (256, 1024)
        )
        L += [
            "",
            f"The host's own parallelism: two processes stepping the serial kernel "
            f"({host['num_envs']} envs each) side by side reach {host['ratio']:.2f}x the "
            f"env-steps/s of one alone ({host['pair']:,.0f} vs {host['alone']:,.0f}); on "
            f"the same host, idle, {k} threads give "
            + (gains or "(no sweep at 256 or 1024 envs)")
            + " over the serial kernel "
            "(batch-size table above).",
        ]
    return L


def _parallel_min():
    from .vector import PARALLEL_MIN_ENVS

    return PARALLEL_MIN_ENVS
