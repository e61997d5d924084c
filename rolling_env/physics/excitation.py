"""The paper's square-wave excitation and the dimensionless description of a drive.

A ``SquareWave`` is fixed by the paper's dimensionless inputs (delta = d2/d1, eps = v/(omega R),
rolling amplitude w = W/a1) and a geometry (R, a1, period tau).  It produces the per-tick
inputs (indentation d, omega R, v) of ``model.Drive.run``: the forth half-period with d1,
+omega R, +v, the back half-period with d2, -omega R, -v.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rolling_env.validation import check_range


@dataclass(frozen=True)
class SquareWave:
    """delta = d2/d1 in [0, 1]; eps = v/(omega R); w = W/a1 > 0 (W: patch travel per half
    period); a1 [m] forth-step contact radius; R [m] sphere radius; tau [s] period;
    direction +1 (forth with the larger force) or -1 (mirrored: the runner moves the other way)."""

    delta: float
    eps: float
    w: float
    a1: float
    R: float
    tau: float = 1e-3
    direction: int = 1

    def __post_init__(self):
        check_range("delta", self.delta, 0.0, 1.0)
        check_range("eps", self.eps, -1e6, 1e6)
        check_range("w", self.w, 0.0, 1e6, lo_open=True)
        check_range("a1", self.a1, 0.0, math.inf, lo_open=True, hi_open=True)
        check_range("R", self.R, 0.0, math.inf, lo_open=True, hi_open=True)
        check_range("tau", self.tau, 0.0, math.inf, lo_open=True, hi_open=True)
        if isinstance(self.direction, (bool, np.bool_)) or self.direction not in (1, -1):
            raise ValueError(f"direction must be +1 or -1, got {self.direction}")

    @property
    def d1(self) -> float:
        return self.a1**2 / self.R

    @property
    def d2(self) -> float:
        return self.delta * self.d1

    @property
    def W(self) -> float:
        """Patch travel per half period [m]."""
        return self.w * self.a1

    @property
    def omega_R(self) -> float:
        """Rolling rate omega R [m/s] (W = omega R tau / 2)."""
        return 2.0 * self.W / self.tau

    @property
    def v(self) -> float:
        return self.eps * self.omega_R

    @property
    def stroke(self) -> tuple[float, float]:
        """Range of the patch centre: [0, W] (forth first), mirrored [-W, 0]."""
        return (0.0, self.W) if self.direction > 0 else (-self.W, 0.0)

    def ticks(self, periods: int, ticks_per_half: int = 1):
        """Per-tick (d, omega_R, v) arrays for ``periods`` full periods; dt_tick =
        tau/2/ticks_per_half."""
        if int(periods) != periods or periods < 1:
            raise ValueError(f"periods must be an integer >= 1, got {periods}")
        if int(ticks_per_half) != ticks_per_half or ticks_per_half < 1:
            raise ValueError(f"ticks_per_half must be an integer >= 1, got {ticks_per_half}")
        one = np.ones(int(ticks_per_half))
        sgn = float(self.direction)
        d = np.tile(np.concatenate([self.d1 * one, self.d2 * one]), periods)
        u = np.tile(np.concatenate([sgn * self.omega_R * one, -sgn * self.omega_R * one]), periods)
        v = np.tile(np.concatenate([sgn * self.v * one, -sgn * self.v * one]), periods)
        return d, u, v

    def dt_tick(self, ticks_per_half: int = 1) -> float:
        return self.tau / 2.0 / ticks_per_half
