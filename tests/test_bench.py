"""The benchmark's arithmetic and probes (timings themselves stay out of the test suite)."""
import math
import subprocess
import sys

import numpy as np
import pytest

from rolling_env import bench
from rolling_env.bench import ratio_bound


@pytest.mark.parametrize("single,serial,one,threads,eff", [
    (136e3, 450e3, 520e3, 2, 1.0), (170e3, 448e3, 523e3, 2, 1.0), (50e3, 1e6, 1e6, 4, 1.0),
    (183.6e3, 945e3, 945e3, 2, 0.94), (136e3, 450e3, 520e3, 2, 0.8)])
def test_ratio_bound_speedup_reaches_the_target(single, serial, one, threads, eff):
    """A physics tick f = speedup_needed times faster makes batched / single equal the target:
    the single env keeps its Python layer and runs the faster tick, the batched env runs the
    faster tick on every thread at the given efficiency (a fraction of perfect scaling)."""
    r = ratio_bound(single, serial, one, threads, target=10.0, efficiency=eff)
    f = r["speedup_needed"]
    step = r["python_us"] + r["physics_us"] / f
    batched_per_step = 1e6 / one / f / (threads * eff)
    assert step / batched_per_step == pytest.approx(10.0, rel=1e-12), r
    if eff < 1.0:  # a lower efficiency needs a faster tick
        assert f > ratio_bound(single, serial, one, threads, target=10.0)["speedup_needed"], r
    assert r["bound"] == pytest.approx(threads * one / single, rel=1e-12)
    assert r["step_us"] == pytest.approx(r["python_us"] + r["physics_us"], rel=1e-12)


def test_ratio_bound_within_reach_needs_no_speedup():
    """When the bound already exceeds the target, the needed speed-up is at most 1."""
    r = ratio_bound(single=50e3, serial=1e6, one_thread=1e6, threads=2, target=10.0)
    assert r["bound"] == pytest.approx(40.0) and r["speedup_needed"] <= 1.0, r


def test_ratio_bound_no_python_layer_is_unreachable():
    """A single env that is all physics cannot gain from batching beyond the threads."""
    r = ratio_bound(single=400e3, serial=400e3, one_thread=400e3, threads=2, target=10.0)
    assert r["bound"] == pytest.approx(2.0) and math.isinf(r["speedup_needed"]), r


def test_memory_probe_ignores_the_parents_peak():
    """The peak-RSS probe the benchmark runs in a subprocess reports that process's own peak:
    after this process has touched 400 MB, a child that imports numpy reports well under
    200 MiB (getrusage's ru_maxrss, used before, carries the parent's peak across fork +
    exec)."""
    big = np.ones(50_000_000)
    code = bench._PEAK + "import numpy\nprint(peak())"
    kib = int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True).stdout)
    assert big[-1] == 1.0 and kib < 200 * 1024, f"child reported a peak of {kib / 1024:.0f} MiB"
