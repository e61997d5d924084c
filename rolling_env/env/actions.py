"""The action mapping of RollingDrive-v0 and its inverse (shared by the env and the baselines).

a0 -> normal force  N = N_min + (a0 + 1)/2 (N_max - N_min)            [N]
a1 -> rolling rate  omega R = a1 omega_R_max                          [m/s], signed
a2 -> creep         v = omega R (1 - a2 creep_max), i.e. 1 - v/(omega R) = a2 creep_max
"""

from __future__ import annotations

import numpy as np


def to_controls(scene, a):
    """Action in [-1, 1]^3 -> (N [N], omega R [m/s], v [m/s])."""
    N = scene.N_min + 0.5 * (a[0] + 1.0) * (scene.N_max - scene.N_min)
    u = a[1] * scene.omega_R_max
    v = u * (1.0 - a[2] * scene.creep_max)
    return N, u, v


def from_controls(scene, N, omega_R, creep):
    """(N [N], omega R [m/s], creep ratio 1 - v/(omega R)) -> action (float32).

    Raises ValueError when a value lies outside what the scene's actuators allow."""
    a0 = 2.0 * (N - scene.N_min) / (scene.N_max - scene.N_min) - 1.0
    a1 = omega_R / scene.omega_R_max
    a2 = creep / scene.creep_max
    a = np.array([a0, a1, a2], dtype=np.float64)
    if np.any(np.abs(a) > 1.0 + 1e-9):
        raise ValueError(
            f"controls (N={N}, omega_R={omega_R}, creep={creep}) lie outside the "
            f"scene's ranges N in [{scene.N_min}, {scene.N_max}], |omega R| <= "
            f"{scene.omega_R_max}, |creep| <= {scene.creep_max}"
        )
    return np.clip(a, -1.0, 1.0).astype(np.float32)
