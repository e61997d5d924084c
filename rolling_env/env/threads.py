"""Threads of the batched env: how many numba threads the caller may use, the threaded kernel's
step at a given count, and ``ThreadPolicy``, which picks the serial or the threaded kernel step
by step from measured step times (``rolling_env.env.vector``'s module docstring says why)."""

from __future__ import annotations

import math
import numbers
import time
from collections import deque
from functools import partial

import numpy as np

from rolling_env.env import _envkernel as EK

# below this many envs the default runs the serial kernel only (module docstring of vector)
PARALLEL_MIN_ENVS = 6


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
