"""Numerical quality: the fast cases of the stability grid and of the work-precision study."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rolling_env import converge, stability


@pytest.fixture(scope="module")
def stability_rows():
    return stability.run(quick=True)


def test_quick_stability_grid_passes(stability_rows):
    """Every quick case: finite, energy not created beyond 1% of the drive work, run time
    bounded, lift-off releases all springs, results converge as the step shrinks."""
    bad = [(r["case"], r["outcome"]) for r in stability_rows if r["status"] != "PASS"]
    assert not bad, f"failed stability cases: {bad}"


def test_energy_never_created(stability_rows):
    for r in stability_rows:
        if math.isfinite(r["residual"]):
            assert r["residual"] > -stability.RESID_TOL, (r["case"], r["residual"])


def test_working_point_error_envelope_falls_at_second_order():
    """Worst case over grid alignments falls monotonically; observed order in [1.6, 2.6]."""
    rows = []
    offsets = np.arange(4) / 4
    from rolling_env import analytic, experiments as ex
    case = (0.7, 0.1, 2.5)
    ref = analytic.eq32(*case)
    res = [8, 16, 32, 64, 128]
    for r in res:
        rows.append(max(abs(ex.working_point(*case, resolution=r, grid_offset=o)["simulated"]
                            - ref) for o in offsets) / ref)
    assert all(b < a for a, b in zip(rows, rows[1:])), f"not monotone: {rows}"
    p = converge.order(res, rows)
    assert 1.6 < p < 2.6, f"observed order {p:.2f} (errors {rows})"


def test_dynamic_run_converges_in_dt_at_first_order():
    from rolling_env import experiments as ex
    vals = [ex.simulate(0.7, 0.995, 2.5, 0.3, mu=0.3, periods=6, resolution=16,
                        n_sub=n)["mean_v_star_over_omega_R"] for n in (20, 40, 80, 160, 1280)]
    errs = np.abs(np.array(vals[:-1]) - vals[-1])
    p = converge.order([20, 40, 80, 160], errs)
    assert 0.7 < p < 1.6, f"observed order in dt {p:.2f}: {vals}"
