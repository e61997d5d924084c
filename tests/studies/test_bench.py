"""The benchmark's arithmetic and probes (timings themselves stay out of the test suite)."""

import math
import subprocess
import sys

import numpy as np
import pytest

from rolling_env.studies import bench_host
from rolling_env.studies.bench_report import ratio_bound


@pytest.mark.parametrize(
    "single,serial,one,threads,eff",
    [
        (136e3, 450e3, 520e3, 2, 1.0),
        (170e3, 448e3, 523e3, 2, 1.0),
        (50e3, 1e6, 1e6, 4, 1.0),
        (183.6e3, 945e3, 945e3, 2, 0.94),
        (136e3, 450e3, 520e3, 2, 0.8),
    ],
)
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
    code = bench_host._PEAK + "import numpy\nprint(peak())"
    kib = int(
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout
    )
    assert big[-1] == 1.0 and kib < 200 * 1024, f"child reported a peak of {kib / 1024:.0f} MiB"


def test_competitor_runs_only_inside_its_block():
    """The busy process of the load conditions runs while the block does and is gone after,
    also when the block raises."""
    with pytest.raises(RuntimeError):
        with bench_host._Competitor(True) as c:
            assert c.proc.poll() is None, "the competing process is not running"
            raise RuntimeError
    assert c.proc.poll() is not None, "the competing process outlived its block"
    with bench_host._Competitor(False) as c:
        assert c.proc is None


def test_load_section_reports_ratios_of_the_same_run():
    """The report's load table divides each condition's rates by that condition's serial
    rate, names the path the default ended on, and sets the threads' idle gains beside the
    host's own parallelism."""
    rows = [
        dict(
            condition="idle",
            serial=100.0,
            threads=180.0,
            default=175.0,
            default_threads=2,
            sb3_batched=90.0,
            sb3_dummy=30.0,
            load_average=1.23,
        ),
        dict(
            condition="busy",
            serial=80.0,
            threads=20.0,
            default=78.0,
            default_threads=1,
            sb3_batched=60.0,
            sb3_dummy=20.0,
        ),
        dict(condition="work", serial=50.0, threads=55.0, default=54.0, default_threads=2),
    ]
    load = dict(
        num_envs=256,
        threads=2,
        sb3_envs=8,
        segment=32,
        work_seconds=1e-3,
        serial_step_seconds=1.1e-3,
        rows=rows,
    )
    host = dict(num_envs=256, alone=100.0, pair=190.0, ratio=1.9)
    sweep = {
        "sweep": [
            dict(num_envs=256, serial=100.0, threaded=170.0, default=168.0),
            dict(num_envs=1024, serial=100.0, threaded=185.0, default=180.0),
        ]
    }
    text = "\n".join(bench_host._load_section(load, host, sweep))
    assert "| 100 | 180 | 175 | 1.75 | 1.80 | 2 threads | 1.2 |" in text, text
    assert "| 80 | 20 | 78 | 0.97 | 0.25 | the serial kernel | nan |" in text, text
    assert "| 90 | 30 | 3.00x |" in text and "| 60 | 20 | 3.00x |" in text, text
    assert "reach 1.90x" in text and "1.70x at 256 envs, 1.85x at 1024 envs" in text, text


def test_load_workers_step_their_envs_on_command():
    """The load table's envs, each in its own process: a step command makes its steps (the
    policy's numpy work between them too) and says what the env steps on; the processes are
    gone after close."""
    w = bench_host._Workers({"serial": "1", "default": "None", "dummy": "dummy"}, 2, 16)
    try:
        assert set(w.layer_seconds) == {"serial", "default", "dummy"}
        seconds, threads = w.go("serial", 5, 2)
        assert seconds > 0 and threads == 1
        assert w.go("default", 3)[1] == 1  # 2 envs: below the threads' minimum, serial
        assert w.go("dummy", 3)[1] == 0  # a DummyVecEnv: no batch
        rates = w.rates(("serial", "default"), 2, 8, 3)
        assert set(rates) == {"serial", "default"} and all(v > 0 for v in rates.values())
    finally:
        w.close()
    assert all(p.poll() is not None for p in w.procs.values())
