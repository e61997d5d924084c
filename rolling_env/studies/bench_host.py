"""Benchmarks of the host rather than the kernel: the batched env's threads beside a busy
process and the caller's own work, the host's own parallelism (two processes side by side),
start-up with a warm and a cold numba cache, and peak memory; and the report's section on
threads under load."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time

from rolling_env.studies.bench_timing import SEGMENT_PAUSE, TOP_ROUNDS, _orders, _whole_episodes

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
    from rolling_env.env.sb3_vec import RollingDriveVecEnv
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
    from rolling_env.env.scenes import load_scene
    from rolling_env.env.threads import max_threads

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
from rolling_env.env.vector import BatchCore
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
