"""Spare cores of the host, from the kernel's CPU counters (Linux ``/proc/stat``).

The batched env's ``ThreadPolicy`` probes a thread count now and then to see whether it pays.
On a host where other processes keep the cores busy it does not, and each probe costs a few
slow steps; ``HostLoad.spare`` tells the policy, before a probe, how many of the cores this
process may run on the other processes left idle lately, so that it probes only thread counts
those cores can hold.

Measured over windows of the caller's steps (``observe`` at each step's start; a window spans
at least ``MIN_WINDOW`` seconds and no pause of the caller's, so that what runs while the
caller waits, another process taking its turn, say, does not count): the busy time of this
process's cores (user, system, irq, softirq and steal: time another virtual machine took
counts as taken; niced processes' time does not, they yield a core to ours) less this
process's own CPU time (all its threads, numba's workers included; child processes count as
others), in cores.  A reading is valid for ``LIFE`` seconds.  The CPU set is the process's
affinity when the reader is built; a CPU quota (cgroup ``cpu.max``) is not read.  Where
``/proc/stat`` cannot be read (not Linux, or a CPU of the set missing from it) ``spare``
returns None and the policy probes as before.
"""

from __future__ import annotations

import os
import time

__all__ = ["HostLoad"]

# user (nice idle iowait) system irq softirq steal: niced processes yield a core to ours, so
# their time does not count as taken; guest time is already in user
_BUSY_FIELDS = (0, 2, 5, 6, 7)


def _cpus() -> tuple:
    try:
        return tuple(sorted(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return tuple(range(os.cpu_count() or 1))


class HostLoad:
    """``spare(now)``: cores of this process's CPU set that other processes left idle over the
    latest window of steps (``observe``), or None where not known.  Times (``now``, seconds)
    come from the caller's clock, which its steps are timed with already.  ``path``,
    ``cpu_time`` (this process's CPU seconds) and ``cpus`` (the CPU set) can be replaced
    (tests)."""

    MIN_WINDOW = 0.1  # seconds: /proc/stat counts in ticks of 10 ms per core (+-0.1 each)
    LIFE = 10.0  # seconds a reading stays valid (a caller that pauses often takes few)

    def __init__(self, path="/proc/stat", cpu_time=time.process_time, cpus=None):
        self.path = path
        self.cpu_time = cpu_time
        self.cpus = _cpus() if cpus is None else tuple(cpus)
        self._names = {f"cpu{c}" for c in self.cpus}
        try:
            self._hz = float(os.sysconf("SC_CLK_TCK"))
        except (AttributeError, ValueError, OSError):
            self._hz = 100.0
        self.value = None  # the latest reading
        self._value_t = 0.0  # when it was taken
        self._open = None  # the open window's start: (clock, busy seconds, own CPU seconds)
        self._off = self._busy() is None  # counters unreadable: never read again

    def _busy(self):
        """Busy seconds of the CPU set since boot, or None."""
        try:
            with open(self.path, "rb") as f:
                text = f.read().decode("ascii", "replace")
        except OSError:
            return None
        busy, seen = 0, 0
        for line in text.splitlines():
            name, _, rest = line.partition(" ")
            if not name.startswith("cpu"):
                break  # the per-CPU lines come first
            if name in self._names:
                fields = rest.split()
                try:
                    busy += sum(int(fields[i]) for i in _BUSY_FIELDS if i < len(fields))
                except ValueError:
                    return None
                seen += 1
        return busy / self._hz if seen == len(self._names) else None

    def _sample(self, now: float):
        busy = self._busy()
        return None if busy is None else (now, busy, self.cpu_time())

    def observe(self, now: float, paused: bool = False) -> None:
        """A step starts at ``now`` (``paused``: after a pause of the caller's, whose time
        says nothing about the steps).  Closes the window opened at an earlier step once it spans
        ``MIN_WINDOW`` seconds, and opens the next; a pause drops the open window, so that a
        window spans the caller's steps only."""
        if self._off:
            return
        if paused:
            self._open = None
            return
        if self._open is not None and now - self._open[0] < self.MIN_WINDOW:
            return
        new = self._sample(now)
        if new is None:
            self._off, self.value = True, None
            return
        if self._open is not None:
            t0, busy0, own0 = self._open
            t1, busy1, own1 = new
            others = max((busy1 - busy0) - (own1 - own0), 0.0) / (t1 - t0)
            self.value = max(len(self.cpus) - others, 0.0)
            self._value_t = t1
        self._open = new

    def spare(self, now: float):
        """Idle cores of the CPU set, less what this process used, over the latest window
        (None: unknown, not measured yet, or measured more than ``LIFE`` seconds before
        ``now``)."""
        if self.value is None or now - self._value_t > self.LIFE:
            return None
        return self.value
