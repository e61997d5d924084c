"""Where the batched env kernel spends its time: Linux ``perf`` on numba's compiled code.

    python tools/profile_kernel.py [--scene default] [--envs 256] [--seconds 8]

Samples the serial batched kernel (``BatchCore`` with ``env_step_serial``, random actions)
with ``perf record -e cpu-clock`` (a timer, so it works on VMs without hardware counters) and
prints each compiled kernel's share of the samples that fall in the kernels' compiled code
(and in libm's ``cbrt``, which the env kernel calls), plus the kernel's time per env-step.
perf cannot name JIT code by itself: the workload compiles the kernels in-process (an empty,
temporary numba cache, so numba keeps the object code), reads each function's address and
size and writes them to ``/tmp/perf-PID.map``, the file perf reads for JIT code (removed once
the samples are read).  Inlined helpers count towards the kernel they are inlined into
(``_tick`` holds the edge cells, the cell ranges and the Newton step).  Needs ``perf``
(Debian: linux-perf) and ``nm`` (binutils).  A developer's tool: nothing in the package or
the tests uses it.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np


def _kernel_dispatchers():
    from rolling_env.env import _envkernel as EK
    from rolling_env.physics import _kernel as K

    mods = (EK, *K.MODULES)
    return [
        v
        for m in mods
        for v in vars(m).values()
        if hasattr(v, "overloads") and v.py_func.__module__ == m.__name__
    ]


def _perf_map_lines(tmp: str) -> list[str]:
    """``start size name`` of every compiled function of the kernels' numba libraries."""
    lines = []
    for disp in _kernel_dispatchers():
        for cres in disp.overloads.values():
            lib = cres.library
            obj = lib.serialize_using_object_code()[2][0]
            path = os.path.join(tmp, "k.o")
            with open(path, "wb") as f:
                f.write(obj)
            nm = subprocess.run(
                ["nm", "-S", "--defined-only", path], capture_output=True, text=True, check=True
            ).stdout
            for row in nm.splitlines():
                parts = row.split()
                if len(parts) == 4 and parts[2] in "tT":
                    addr = lib.get_pointer_to_function(parts[3])
                    if addr:
                        lines.append(f"{addr:x} {int(parts[1], 16):x} {parts[3]}")
    return lines


def workload(scene: str, envs: int, seconds: float) -> None:
    """Run under perf: compile, write the perf map, then step the batch for ``seconds``."""
    from rolling_env.env import _envkernel as EK
    from rolling_env.env.vector import BatchCore

    core = BatchCore(envs, scene=scene)
    core._step_fn = EK.env_step_serial
    acts = np.random.default_rng(0).uniform(-1, 1, (100, envs, 3))
    core.seed(0)
    core.reset()
    for a in acts[:20]:
        core.step(a)
    with tempfile.TemporaryDirectory() as tmp:
        lines = _perf_map_lines(tmp)
    map_path = f"/tmp/perf-{os.getpid()}.map"
    with open(map_path, "w") as f:
        f.write("\n".join(lines) + "\n")
    if "PROFILE_KERNEL_MAP" in os.environ:  # tell the parent, which removes it
        with open(os.environ["PROFILE_KERNEL_MAP"], "w") as f:
            f.write(map_path)
    t0 = time.perf_counter()
    passes = 0
    while time.perf_counter() - t0 < seconds:
        core.seed(0)
        core.reset()
        for a in acts:
            core.step(a)
        passes += 1
    per_step = (time.perf_counter() - t0) / (passes * len(acts) * envs)
    print(f"{per_step * 1e6:.3f} us per env-step while sampled (sampling slows it down)")


def _short(sym: str) -> str:
    m = re.search(r"(?:_envkernel|_kernel)\d+(\w+?)B\d", sym)
    return m.group(1) if m else sym.split("(")[0][:40]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="default")
    ap.add_argument("--envs", type=int, default=256)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--workload", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.workload:
        workload(args.scene, args.envs, args.seconds)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        map_note = os.path.join(tmp, "map_path")
        env = dict(
            os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba"), PROFILE_KERNEL_MAP=map_note
        )
        try:
            rec = subprocess.Popen(
                [
                    "perf",
                    "record",
                    "-q",
                    "-e",
                    "cpu-clock",
                    "-F",
                    "5000",
                    "-o",
                    data,
                    "--",
                    sys.executable,
                    __file__,
                    "--workload",
                    "--scene",
                    args.scene,
                    "--envs",
                    str(args.envs),
                    "--seconds",
                    str(args.seconds),
                ],
                env=env,
            )
        except FileNotFoundError:
            print("perf not found (Debian: apt install linux-perf)")
            return 1
        code = rec.wait()
        try:
            if code != 0:
                print(
                    f"perf record failed (exit {code}): is perf allowed here "
                    "(/proc/sys/kernel/perf_event_paranoid)?"
                )
                return 1
            script = subprocess.run(
                ["perf", "script", "-i", data, "-F", "ip,sym"],
                capture_output=True,
                text=True,
                check=True,
            ).stdout
        finally:
            if os.path.exists(map_note):  # the workload's perf map, once perf has read it
                with open(map_note) as f:
                    path = f.read().strip()
                if path.startswith("/tmp/perf-") and os.path.exists(path):
                    os.remove(path)
    counts = collections.Counter()
    for row in script.splitlines():
        sym = row.strip().partition(" ")[2]
        if "rolling_env" in sym or sym.startswith("__cbrt"):
            counts[_short(sym)] += 1
    total = sum(counts.values())
    if not total:
        print("no samples in the compiled kernels (did the workload write its perf map?)")
        return 1
    print(f"{args.scene}, {args.envs} envs: share of {total} samples in compiled code")
    for name, n in counts.most_common():
        print(f"  {name:20s} {100 * n / total:5.1f}%")
    return 0


if __name__ == "__main__":
    sys.exit(main())
