"""Natively batched RollingDrive-v0: one compiled call steps N envs.

``BatchCore`` holds N envs' state with a leading env axis and steps them all in one call of the
env kernel (the same ``_envkernel`` tick the single env runs with a batch of one, so the
transitions are bit-identical to N single envs).  Two thin adapters:

* ``RollingDriveVectorEnv`` (``gymnasium.vector.VectorEnv``, NEXT_STEP autoreset), the
  ``vector_entry_point`` of ``gym.make_vec("RollingDrive-v0", num_envs=N)``;
* ``RollingDriveVecEnv`` (Stable-Baselines3 ``VecEnv``, same-step autoreset with
  ``terminal_observation`` and ``TimeLimit.truncated``), for training.  It lives in
  ``rolling_env.sb3_vec`` so that ``gym.make_vec`` imports neither Stable-Baselines3 nor torch;
  importing it from here still works (``__getattr__`` below).

Seeding follows Gymnasium: env i of a batch seeded s behaves like a single env seeded s + i.

Threads (``num_threads``).  Whether numba's threads pay depends on the host's load of the
moment, not on the batch alone: on a 2-vCPU VM the threaded kernel at 256 envs ran at 0.3x the
serial kernel one hour and 1.8x the next, because worker threads that wait (spinning, with
numba's OpenMP layer) between two steps compete with the Python thread and with other
processes for the cores.  So by default (``num_threads=None``) a ``ThreadPolicy`` picks the
path step by step from what it measures: it runs the faster of the serial kernel and the
threaded kernel (at 2, 4, ... up to the calling thread's numba thread count), and now and then
times a few steps of the others, the time from one step's start to the next, so that the
Python work between steps counts too.  The probes of a slower path are spaced so that they
cost at most ``ThreadPolicy.BUDGET`` of the time, and a larger thread count is not probed while
other processes leave too few of this process's cores idle (``rolling_env.hostload``, from
Linux's CPU counters over the caller's recent steps): on a busy host threads lose, and each
probe would cost a few slow steps.  Transitions are bit-identical on every path,
so switching changes no result.  ``num_threads=1`` always runs the serial kernel, ``k`` the
threaded kernel on k threads.  The thread count is set for each threaded step only and
restored after it (numba keeps it per calling thread); the threading layer and its wait policy
stay numba's (``NUMBA_THREADING_LAYER``, ``OMP_WAIT_POLICY``: nothing here sets them).  Below
``PARALLEL_MIN_ENVS`` envs the default runs the serial kernel only: the threads never paid
there on the 2-core machine (0.61-0.63x at 1 env, 0.90-0.98x at 4).
"""

from __future__ import annotations

import math
import numbers
import os
import time
from collections import deque
from collections.abc import Mapping
from functools import partial

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from . import _envkernel as EK
from . import _kernel as K
from .env import (
    OBS_NAMES,
    build_drive,
    check_action_dtype,
    check_actions,
    check_time_limit,
    info_arrays,
    info_dict,
    load_actions,
    raise_step_error,
    sample_target,
    target_option,
)
from .hostload import HostLoad
from .model import CellViews
from .scenes import load_scene

PARALLEL_MIN_ENVS = 6

__all__ = [
    "BatchCore",
    "RollingDriveVectorEnv",
    "RollingDriveVecEnv",  # noqa: F822 (module __getattr__ below)
    "make_vector_env",
    "PARALLEL_MIN_ENVS",
    "ThreadPolicy",
    "check_num_threads",
]


def _check_seed(seed, name: str) -> int:
    """A seed as a Python int: a non-negative integer (numpy integers too), not a bool."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer or None, got {seed!r}")
    return int(seed)


def _physical_memory() -> float:
    """Bytes of physical memory (inf where the OS does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return math.inf


def _check_memory(n: int, cell_bytes: int, scene) -> None:
    """A batch whose cell arrays alone exceed the machine's memory is a ValueError naming
    num_envs and the scene keys that size an env's cells (numpy's "Unable to allocate 7 PiB"
    named neither)."""
    need = float(n) * cell_bytes
    have = _physical_memory()
    if need > have:
        raise ValueError(
            f"num_envs = {n} envs x {cell_bytes / 2**20:.3g} MiB of cell state each "
            f"(resolution = {scene.resolution!r}, grid_levels = {scene.grid_levels!r}, "
            f"stroke_roll = {scene.stroke_roll!r}) need {need / 2**30:.3g} GiB, more than this "
            f"machine's {have / 2**30:.3g} GiB: lower num_envs, or the scene's resolution, "
            "grid_levels or stroke"
        )


def max_threads() -> int:
    """The most threads the threaded kernel can use: numba's NUMBA_NUM_THREADS."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)


def check_num_threads(num_threads, name: str = "num_threads"):
    """``num_threads`` checked: None (chosen at run time) or an int in [1, NUMBA_NUM_THREADS];
    anything else is a ValueError naming ``name`` and the range."""
    if num_threads is None:
        return None
    hi = max_threads()
    if (
        isinstance(num_threads, (bool, np.bool_))
        or not isinstance(num_threads, numbers.Integral)
        or not 1 <= num_threads <= hi
    ):
        raise ValueError(
            f"{name} must be None (chosen at run time) or an integer in [1, {hi}] "
            f"(1: serial kernel; at most numba's NUMBA_NUM_THREADS), got "
            f"{num_threads!r}"
        )
    return int(num_threads)


def _callers_threads() -> int:
    import numba

    return numba.get_num_threads()


def thread_choices(num_envs: int, most: int) -> tuple:
    """Thread counts the default policy chooses from for ``num_envs`` envs, with at most
    ``most`` threads: 1 (the serial kernel), then 2, 4, ... and ``most`` (no more than the
    envs); only 1 below ``PARALLEL_MIN_ENVS`` envs."""
    top = min(most, num_envs)
    if num_envs < PARALLEL_MIN_ENVS or top < 2:
        return (1,)
    counts, k = [1], 2
    while k < top:
        counts.append(k)
        k *= 2
    return tuple(counts + [top])


def _threaded_step(threads: int, *args):
    """``_envkernel.env_step_parallel`` on ``threads`` threads.  numba keeps the thread count
    per calling thread: it is set for this call only and restored after it, so the caller's
    other numba code keeps its own setting (setting it inside the kernel would make numba
    refuse to cache it).  Both calls are skipped where the count is already right."""
    import numba

    before = numba.get_num_threads()
    if before == threads:
        return EK.env_step_parallel(*args)
    numba.set_num_threads(threads)
    try:
        return EK.env_step_parallel(*args)
    finally:
        numba.set_num_threads(before)


def _kernel_for(threads: int):
    """The step kernel for a thread count: the serial kernel for 1, else the threaded one."""
    return EK.env_step_serial if threads == 1 else partial(_threaded_step, threads)


def _median(xs) -> float:
    s = sorted(xs)
    m = len(s) // 2
    return s[m] if len(s) % 2 else 0.5 * (s[m - 1] + s[m])


class ThreadPolicy:
    """Picks the thread count of each step from measured step times (``BatchCore``'s step
    kernel when ``num_threads`` is None; called like ``_envkernel.env_step_serial``).

    A step costs the kernel call plus the time until the next step starts: the Python work
    between steps counts too, since threads that spin after a step slow it down on a busy host;
    a time between steps longer than ``PAUSE`` step times is the caller's pause (a learner's
    update, say) and counts as ``PAUSE`` step times.  A choice's step time is the mean over its
    recent steps, at least ``WINDOW`` of them and at least ``SPAN`` seconds: on a busy host
    threads run fast while the core is theirs and stall for a time slice when it is not, so
    fewer steps say little.  The choice in use (``current``) is measured as it runs, its
    estimate renewed every ``RENEW`` steps and after a step twice as long as it.  Each other
    choice is probed now and then: after untimed steps that pay for the switch (the first, and
    where threads were left, those until the steps run at the choice's pace again, ``SETTLE``
    seconds at least: OpenMP's worker threads spin for a few milliseconds after a threaded
    step, and on a busy host the steps right after it pay for that), ``PROBE`` timed steps
    spanning ``SPAN`` seconds, fewer where they already cost more than the probe may (a choice
    100x slower is dropped after one).  The probed choice is taken over when its estimate beats
    the current one.  A choice's next probe comes ``max(MIN_STEPS, cost / (BUDGET * t))`` steps
    after its last, ``cost`` being what that probe and the way back cost over staying on the
    current choice and ``t`` the current step time (renewed with it), so probing a slower
    choice costs about ``BUDGET`` of the time.  A choice that beats the current one by
    ``GUARD`` by the latest measures is likely a gain: it is probed without the ``MIN_STEPS``
    floor and with ``GUARD_BUDGET`` (what its switches cost is soon made up); and for
    ``WINDOW`` steps after a switch the choice left is probed at once if the new one runs
    ``GUARD`` times slower than it did (a lucky probe costs a few steps).  Steps are counted,
    not clock time, so that the spacing holds however long the caller pauses.  Thread counts
    change which thread computes an env, never its result, so no switch changes a transition.
    ``clock`` (seconds) can be replaced, e.g. by a test, which may also drive ``next`` and
    ``done`` itself."""

    PROBE = 4  # timed steps of a probe at least
    WINDOW = 16  # recent steps of the current choice kept at least
    SPAN = 0.025  # seconds a probe and the current choice's steps kept span at least
    RENEW = 8  # steps between two renewals of the current choice's estimate
    PAUSE = 4  # a longer time between steps counts as this many step times
    BUDGET = 0.01  # most of the time that probing a slower choice may cost
    MIN_STEPS = 32  # steps between two probes of one choice at least
    GUARD = 1.25  # another choice this much faster than the current: probe it soon
    GUARD_BUDGET = 0.05  # most of the time its probes may cost then
    SETTLE = 0.01  # seconds after leaving threads during which steps are not timed,
    # at least (see _settled)
    RETURNS = 5  # recent costs of the way back from a probe kept (their median counts)
    ROOM = 0.5  # k threads are probed while at least k - ROOM cores are spare (see _no_room)
    LOAD_GAP = 0.05  # seconds between steps that end the host load's window (see next)

    def __init__(self, choices, clock=time.perf_counter, load=None):
        self.choices = tuple(int(k) for k in choices)
        if not self.choices:
            raise ValueError("choices must hold at least one thread count")
        self.clock = clock
        self.load = load  # a HostLoad, or None: probe whatever the host's load
        self.gated = 0  # probes put off for want of spare cores
        self._held = [0] * len(self.choices)  # step before which a put-off probe waits
        self._kernels = [_kernel_for(k) for k in self.choices]
        n = len(self.choices)
        self.estimate = [math.nan] * n  # seconds per step of each choice, as last measured
        self.current = 0  # index of the choice in use; starts serial
        self.probing = None  # index of the choice under probe, or None
        self.steps = 0  # steps started
        self.probes = 0  # probes started
        self.switches = 0  # times the current choice changed
        self._probe = [0.0, 0]  # (seconds, steps) of the running probe's timed steps
        self._probe_spent = [0.0, 0]  # (seconds, steps) of the running probe, untimed too
        self._window = deque()  # step times of the current choice, oldest first
        self._window_sum = 0.0
        self._fresh = 0  # timed steps of the current choice since a probe
        self._left = [0] * n  # step at which each choice last ran
        self._spent = [(0.0, 0)] * n  # (seconds, steps) of each choice's last probe
        self._due = [0] * n  # step from which each choice may be probed
        self._next_due = 0 if n > 1 else math.inf  # the earliest of another choice's
        self._urgent = None  # a choice to probe at once (see _watch_step)
        self._watch = None  # after a switch: [choice left, its estimate, sum, n]
        self._returns = deque(maxlen=self.RETURNS)  # excess seconds of the way back
        self._returning = None  # excess seconds of the way back so far, or None
        self._return_cost = 0.0  # the median of _returns
        self._settle_end = None  # while threads left may spin: the earliest end
        self._settle_limit = 0.0  # and the latest
        self._start = self._end = None  # clock at the previous step's start and end
        self._prev = self._before = -1  # choices of the previous step and the one before

    @property
    def threads(self) -> int:
        """Thread count of the choice in use (1: the serial kernel)."""
        return self.choices[self.current]

    def next(self) -> int:
        """Index of the choice for the step about to start; times the previous step."""
        now = self.clock()
        prev = self._prev
        end = self._end
        if end is not None:
            t = self.estimate[self.current]
            gap = now - end
            paused = gap > self.PAUSE * t
            step = end - self._start + (self.PAUSE * t if paused else gap)
            timed = prev == self._before and (self._settle_end is None or self._settled(step))
            if timed and prev == self.current and self._returning is None and self._watch is None:
                self._add(step)  # the common case, kept short
            else:
                self._record(prev, step, timed)
        # read on every choice, so that the reading is current when the load drives the
        # policy off the threads; the caller's own work between steps is its own CPU time,
        # so only a long gap (a learner's update, another process's turn) ends the window
        if self.load is not None:
            self.load.observe(now, end is None or gap > self.LOAD_GAP)
        if self.probing is not None:
            seconds, timed = self._probe
            if (timed >= self.PROBE and seconds >= self.SPAN) or (
                timed >= 1 and self._probe_too_dear(seconds, timed)
            ):
                self._decide(now)
        if (
            self.steps >= self._next_due
            and self.probing is None
            and self._returning is None
            and self._fresh >= self.PROBE
        ):
            j = min((d, j) for j, d in enumerate(self._due) if j != self.current)[1]
            if self._no_room(j, now):
                return self._pick(prev, now)
            self.estimate[self.current] = self._window_sum / len(self._window)
            self.probing = j
            self._urgent = None if self._urgent == j else self._urgent
            self._probe = [0.0, 0]
            self._probe_spent = [0.0, 0]
            self.probes += 1
            self._leave(self.current, j, now)
        return self._pick(prev, now)

    def _pick(self, prev: int, now: float) -> int:
        pick = self.current if self.probing is None else self.probing
        self._before, self._prev = prev, pick
        self._start, self._end = now, None
        self.steps += 1
        return pick

    def _no_room(self, j: int, now: float) -> bool:
        """Whether a probe of choice j, more threads than the current choice, is put off:
        the other processes left fewer than ``threads - ROOM`` cores of this process's CPU
        set idle over the latest window of steps (``load``, a ``HostLoad``), so its threads
        would wait for cores.  It is then due no sooner than ``MIN_STEPS`` steps later.  A probe of
        fewer threads, one without a reading, and the urgent probe of the choice just left
        (``_watch_step``) always run."""
        k = self.choices[j]
        if self.load is None or k <= self.choices[self.current] or j == self._urgent:
            return False
        room = self.load.spare(now)
        if room is None or room >= k - self.ROOM:
            return False
        self.gated += 1
        self._held[j] = self.steps + self.MIN_STEPS
        self._plan()
        return True

    def done(self) -> None:
        """The step started by the last ``next`` has left the kernel."""
        self._end = self.clock()

    def _add(self, step: float) -> None:
        """One more timed step of the current choice: kept, the oldest dropped while at
        least ``WINDOW`` steps spanning ``SPAN`` seconds remain."""
        w = self._window
        w.append(step)
        self._window_sum += step
        while len(w) > self.WINDOW and self._window_sum - w[0] >= self.SPAN:
            self._window_sum -= w.popleft()
        self._fresh += 1
        # renewed every RENEW steps, and at once after a step far slower than the estimate
        # (the host's load may have just changed)
        if self._fresh % self.RENEW == 0 or step > 2 * self.estimate[self.current]:
            self.estimate[self.current] = self._window_sum / len(w)
            self._plan()

    def _record(self, choice: int, step: float, timed: bool) -> None:
        """File the last step's time under the choice it ran (see ``next``)."""
        if choice == self.probing:
            self._probe_spent[0] += step
            self._probe_spent[1] += 1
            if timed:
                self._probe[0] += step
                self._probe[1] += 1
        elif choice == self.current:
            if not timed:
                if self._returning is not None:
                    self._returning += max(step - self.estimate[choice], 0.0)
                return
            if self._returning is not None:  # back on the current choice, settled
                self._returns.append(self._returning)
                self._return_cost = _median(self._returns)
                self._returning = None
                self._plan()
            if self._watch is not None:
                self._watch_step(step)
            self._add(step)

    def _leave(self, old: int, new: int, now: float) -> None:
        """The running choice changes: steps are untimed until the threads of ``old`` that
        ``new`` does not use have stopped spinning (the first step is untimed anyway)."""
        if self.choices[new] < self.choices[old]:
            self._settle_end = now + self.SETTLE
            self._settle_limit = now + 10 * self.SETTLE

    def _settled(self, step: float) -> bool:
        """Whether the threads left have stopped spinning, by the last step (of the running
        choice): ``SETTLE`` seconds have passed and the step took no more than ``GUARD``
        times the choice's estimate; on a crowded host a spinning thread may have to wait
        for a core before it spins on, so the wait ends at ``10 SETTLE`` at the latest."""
        e = self.estimate[self._prev]
        if self._start >= self._settle_limit or (
            self._start >= self._settle_end and not step > self.GUARD * e
        ):
            self._settle_end = None
            return True
        return False

    def _probe_too_dear(self, seconds: float, timed: int) -> bool:
        """The running probe's timed steps already cost more over the current choice than
        ``BUDGET`` of the steps since its choice last ran (and at least two steps) buy."""
        t = self.estimate[self.current]
        excess = seconds - timed * t
        return excess > max(self.BUDGET * t * (self.steps - self._left[self.probing]), 2 * t)

    def _decide(self, now: float) -> None:
        j, cur = self.probing, self.current
        seconds, timed = self._probe
        self.probing = None
        self._fresh = 0
        self.estimate[j] = seconds / timed
        self.estimate[cur] = self._window_sum / len(self._window)
        self._spent[j] = tuple(self._probe_spent)
        self._left[j] = self.steps
        if self.estimate[j] < self.estimate[cur]:
            self.current = j
            # the probe's mean stands for its steps until the choice's own steps replace it
            self._window = deque([self.estimate[j]] * timed)
            self._window_sum = seconds
            self._fresh = self.PROBE
            self.switches += 1
            self._left[cur] = self.steps
            self._watch = [cur, self.estimate[cur], 0.0, 0]
        else:
            self._returning = 0.0
            self._leave(j, cur, now)
        self._plan()

    def _watch_step(self, step: float) -> None:
        """A step of a newly taken choice: if those since the switch run ``GUARD`` times
        slower than the choice left did, probe that one at once."""
        w = self._watch
        w[2] += step
        w[3] += 1
        if w[2] > self.GUARD * w[1] * w[3]:
            self._watch = None
            self._urgent = w[0]
            self._plan()
        elif w[3] >= self.WINDOW:
            self._watch = None

    def _plan(self) -> None:
        """When each other choice is probed next, from the latest estimates."""
        cur, t = self.current, self.estimate[self.current]
        nearest = math.inf
        for j, e in enumerate(self.estimate):
            if j == cur:
                continue
            if j == self._urgent or e != e or not t > 0:
                due = self.steps  # untried, or the watch after a switch says so (e nan: e != e)
            else:
                seconds, steps = self._spent[j]
                cost = max(seconds - steps * t, 0.0) + self._return_cost
                if e * self.GUARD < t:  # likely a gain: only the switches are paid for
                    due = self._left[j] + math.ceil(cost / (self.GUARD_BUDGET * t))
                else:
                    due = self._left[j] + max(self.MIN_STEPS, math.ceil(cost / (self.BUDGET * t)))
            if j != self._urgent:
                due = max(due, self._held[j])
            self._due[j] = due
            nearest = min(nearest, due)
        self._next_due = nearest

    def kernel(self):
        """The kernel for the step about to start (``next``); call ``done`` after it."""
        return self._kernels[self.next()]

    def __call__(self, *args):
        bad = self._kernels[self.next()](*args)
        self._end = self.clock()  # as done(); a step that raised is not timed (_end None)
        return bad


class BatchCore(CellViews):
    """N envs of one scene: state arrays with a leading env axis, ``step``, ``reset(mask)``.

    ``num_threads``: None (default) picks the serial or the threaded kernel and its thread
    count step by step from measured step times (``ThreadPolicy``, ``thread_policy``); 1
    always runs the serial kernel; k in [2, NUMBA_NUM_THREADS] the threaded kernel on k
    threads.  ``threads`` says what the batch steps on now."""

    #: attributes holding one entry per env (leading axis num_envs); the rest is shared
    PER_ENV = frozenset(
        {
            "cells",
            "U",
            "A",
            "B",
            "L",
            "st",
            "p",
            "target",
            "steps",
            "act",
            "out",
            "obs",
            "extra",
            "rew",
            "trunc",
            "rngs",
        }
    )

    def __init__(
        self, num_envs: int, scene="default", max_episode_steps=None, num_threads=None, **overrides
    ):
        if (
            isinstance(num_envs, (bool, np.bool_))
            or not isinstance(num_envs, numbers.Integral)
            or num_envs < 1
        ):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        n = int(num_envs)
        self.num_threads = check_num_threads(num_threads)
        self.num_envs = n
        self.scene = load_scene(scene, **overrides)
        if self.scene.randomize:  # one compiled call steps one physics for the whole batch
            keys = ", ".join(k for k, _, _ in self.scene.randomize)
            raise ValueError(
                f"scene {self.scene.name!r} draws {keys} per episode (randomize): "
                "the batched envs step one physics for all envs; use single "
                "envs (gym.make, make_vec(..., vectorization_mode='sync'), SB3's "
                "DummyVecEnv: agents.train --vec-env dummy)"
            )
        self.max_episode_steps = check_time_limit(max_episode_steps, self.scene)
        drive, self.a_max = build_drive(self.scene)
        self.drive = drive  # template (grid, scales)
        self.features = drive.kernel_features + (None,)  # (mu, mass, load, ledger)
        self.sv = EK.scene_vector(self.scene, self.a_max, drive)
        _check_memory(n, drive.cells.nbytes, self.scene)
        self.cells = np.zeros((n,) + drive.cells.shape)  # per env: U, A, B (and L), see _kernel
        self.st = np.zeros((n, K.N_STATE))
        self.p = np.tile(drive._p, (n, 1))
        self.target = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.act = np.zeros((n, 3))
        self.out = np.zeros((n, K.N_OUT))
        self.obs = np.zeros((n, EK.N_OBS), dtype=np.float32)
        self.extra = np.zeros((n, EK.N_X))
        self.rew = np.zeros(n)  # written by the kernel: reward and steps >= max_episode_steps
        self.trunc = np.zeros(n, dtype=np.bool_)
        self.rngs = [seeding.np_random(None)[0] for _ in range(n)]
        self.thread_policy = None  # the ThreadPolicy when num_threads is None, else None
        if self.num_threads is not None:
            self._step_fn = _kernel_for(self.num_threads)
        else:
            # the caller's numba thread count caps the choices (asked only where threads may
            # run: it starts numba's thread pool)
            choices = (1,) if n < PARALLEL_MIN_ENVS else thread_choices(n, _callers_threads())
            if len(choices) == 1:
                self._step_fn = _kernel_for(choices[0])
            else:
                # probes only thread counts that the cores other processes leave idle hold
                self.thread_policy = self._step_fn = ThreadPolicy(choices, load=HostLoad())

    @property
    def threads(self) -> int:
        """Threads the batch steps on now (1: the serial kernel)."""
        if self.thread_policy is not None:
            return self.thread_policy.threads
        return self.num_threads or 1

    def seed(self, seed=None):
        """Env i gets seed + i (Gymnasium's convention); None draws fresh entropy.  A sequence
        of num_envs seeds (int or None each) seeds env i with seed[i] (None: left as is).
        Seeds are non-negative integers (numpy integers included); anything else raises."""
        if isinstance(seed, np.ndarray) and seed.ndim == 0:
            seed = seed.item()
        if isinstance(seed, (list, tuple, np.ndarray)):
            if len(seed) != self.num_envs:
                raise ValueError(
                    f"seed must be an int, None or a sequence of num_envs = "
                    f"{self.num_envs} seeds, got {len(seed)} seeds"
                )
            seeds = [
                None if s is None else _check_seed(s, f"seed[{i}]") for i, s in enumerate(seed)
            ]
            for i, s in enumerate(seeds):
                if s is not None:
                    self.rngs[i] = seeding.np_random(s)[0]
            return
        base = None if seed is None else _check_seed(seed, "seed")
        for i in range(self.num_envs):
            self.rngs[i] = seeding.np_random(None if base is None else base + i)[0]

    def reset(self, mask=None, options=None) -> None:
        """Reset the envs where ``mask`` is True (all when None).  ``options``: one dict for
        every env, or a sequence of num_envs dicts (or None), one per env."""
        if mask is not None:
            m = np.asarray(mask)
            if m.dtype != np.bool_ or m.shape != (self.num_envs,):
                raise ValueError(
                    f"mask must be None or a bool array of shape "
                    f"({self.num_envs},) (True: reset that env), got {mask!r}"
                )
        idx = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        # every env's options checked before any env changes: a bad one resets nothing
        given = self.check_options(options, idx)
        for i, g in zip(idx, given):  # each env draws from its own generator
            self.target[i] = sample_target(self.scene, self.rngs[i], g)
        self.cells[idx] = 0.0  # the scratch and level-grid rows too
        self.st[idx] = 0.0
        self.steps[idx] = 0
        self.extra[idx] = 0.0
        self.extra[idx, EK.X_SAT] = 1.0
        for i in idx:
            EK.reset_obs(i, self.sv, self.target, self.obs)

    def check_options(self, options, idx=None) -> list:
        """The target each env of ``idx`` (default all) asks for (None: draw one), checked:
        ``options`` is None, one dict for every env or a sequence of num_envs dicts (or
        None).  Raises before anything changes."""
        per_env = isinstance(options, (list, tuple, np.ndarray))
        if per_env and len(options) != self.num_envs:
            raise ValueError(
                f"options must be a dict or a sequence of num_envs = "
                f"{self.num_envs} dicts, got {len(options)}"
            )
        idx = range(self.num_envs) if idx is None else idx
        return [target_option(self.scene, options[i] if per_env else options) for i in idx]

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance every env one tick; returns (obs float32, rewards, truncated)."""
        a = load_actions(actions, (self.num_envs, 3), self.act)
        policy = self._step_fn if self._step_fn is self.thread_policy else None
        fn = self._step_fn if policy is None else policy.kernel()
        bad = fn(
            self.act,
            self.sv,
            self.target,
            self.steps,
            self.cells,
            self.st,
            self.p,
            self.out,
            self.obs,
            self.extra,
            self.rew,
            self.trunc,
            self.max_episode_steps,
            *self.features,
        )
        if policy is not None:
            policy.done()
        if bad:
            raise_step_error(bad, a, (self.num_envs, 3), self.st, self.scene, self.extra)
        return self.obs.copy(), self.rew.copy(), self.trunc.copy()

    def info(self, i: int) -> dict:
        return info_dict(self.extra[i], self.target[i])

    def observation_space(self):
        return spaces.Box(-EK.OBS_BOUND, EK.OBS_BOUND, (len(OBS_NAMES),), np.float32)


# ----------------------------------------------------------------------------- Gymnasium
def make_vector_env(num_envs: int = 1, max_episode_steps=None, **kwargs):
    """``vector_entry_point`` of RollingDrive-v0 (``gym.make_vec(..., num_envs=N)``)."""
    return RollingDriveVectorEnv(num_envs, max_episode_steps=max_episode_steps, **kwargs)


def _gym_vector_base():
    from gymnasium.vector import VectorEnv

    return VectorEnv


class RollingDriveVectorEnv(_gym_vector_base()):
    """Gymnasium vector env over ``BatchCore`` with NEXT_STEP autoreset: the step after an
    episode ends resets that env and returns its first observation, reward 0 and no flags."""

    def __init__(self, num_envs: int = 1, max_episode_steps=None, render_mode=None, **kwargs):
        from gymnasium.vector import AutoresetMode
        from gymnasium.vector.utils import batch_space

        if render_mode is not None:
            raise ValueError("the batched env does not render; use a single env to look at it")
        self.core = BatchCore(num_envs, max_episode_steps=max_episode_steps, **kwargs)
        self.num_envs = self.core.num_envs
        self.metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}
        self.render_mode = None
        self.single_observation_space = self.core.observation_space()
        self.single_action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._not_reset = np.ones(self.num_envs, dtype=bool)  # never reset yet
        self._any_not_reset = True

    def reset(self, *, seed=None, options=None):
        """Reset every env, or with ``options={"reset_mask": m}`` (a bool array, one entry per
        env, as Gymnasium's own vector envs take it) only those where m is True: seeds apply
        to them only, and the infos' ``_key`` masks are m.  Seeds and options are checked
        before anything changes."""
        mask = None
        if isinstance(options, Mapping) and "reset_mask" in options:
            options = dict(options)  # the caller's dict is left as it was
            mask = self._reset_mask(options.pop("reset_mask"))
            options = options or None
        self.core.check_options(options, None if mask is None else np.flatnonzero(mask))
        if seed is not None:
            if mask is not None:
                if isinstance(seed, np.ndarray) and seed.ndim == 0:
                    seed = seed.item()
                if isinstance(seed, numbers.Integral) and not isinstance(seed, (bool, np.bool_)):
                    seed = [int(seed) + i for i in range(self.num_envs)]
                if isinstance(seed, (list, tuple, np.ndarray)) and len(seed) == self.num_envs:
                    seed = [s if m else None for s, m in zip(seed, mask)]
            self.core.seed(seed)  # int: env i gets seed + i; or one seed (or None) per env
            if isinstance(seed, numbers.Integral):
                self.action_space.seed(int(seed))
        self.core.reset(mask, options)
        self._autoreset[slice(None) if mask is None else mask] = False
        self._not_reset[slice(None) if mask is None else mask] = False
        self._any_not_reset = bool(self._not_reset.any())
        return self.core.obs.copy(), self._infos(mask)

    def _reset_mask(self, m) -> np.ndarray:
        if not (
            isinstance(m, np.ndarray)
            and m.dtype == np.bool_
            and m.shape == (self.num_envs,)
            and m.any()
        ):
            raise ValueError(
                f"options['reset_mask'] must be a numpy bool array of shape "
                f"({self.num_envs},) with at least one True, got {m!r}"
            )
        return m.copy()

    def step(self, actions):
        if self._any_not_reset:  # as gym.make's OrderEnforcing does for each env of "sync"
            from gymnasium.error import ResetNeeded

            raise ResetNeeded(
                f"Cannot call step() before reset(): env(s) "
                f"{np.flatnonzero(self._not_reset).tolist()[:10]} were never "
                "reset"
            )
        actions = check_action_dtype(actions)  # range and finiteness are checked by core.step
        if actions.shape != (self.num_envs, 3):  # before np.where below could broadcast it
            check_actions(actions, (self.num_envs, 3))  # raises naming the shape
        was_done = self._autoreset.copy()
        any_done = np.count_nonzero(was_done) > 0  # a quarter of the time of .any() here
        obs, rew, trunc = self.core.step(
            np.where(was_done[:, None], 0.0, actions) if any_done else actions
        )
        if any_done:
            self.core.reset(was_done)  # the envs that ended last step start over instead
            obs = self.core.obs.copy()
            rew[was_done] = 0.0
            trunc[was_done] = False
        term = np.zeros(self.num_envs, dtype=bool)  # the drive has no terminal state
        self._autoreset = trunc.copy()  # trunc | term; a copy: the caller may change trunc
        return obs, rew, term, trunc, self._infos()

    def _infos(self, mask=None) -> dict:
        """The single env's info keys as arrays with Gymnasium's ``_key`` masks (every env
        reports each key, or those of ``mask``; an env reset this step reports its reset info,
        as in "sync")."""
        d = info_arrays(self.core.extra, self.core.target)
        masks = np.ones((len(d), self.num_envs), dtype=bool)  # one allocation, rows as views
        if mask is not None:
            masks[:] = mask
            for v in d.values():
                v[~mask] = 0  # Gymnasium's fill for envs without info
        d.update(zip(_MASK_KEYS, masks, strict=True))
        return d


_MASK_KEYS = tuple("_" + k for k in info_arrays(np.zeros((1, EK.N_X)), np.zeros(1)))
