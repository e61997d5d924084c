"""The physical parameters' allowed ranges, shared by the scenes and the physics experiments:
wide but bounded, so that every derived scale (contact radius, forces, masses, rates in kernel
units) stays a normal float.  Each entry is key: (type, lo, hi, lo_open, allow_inf)."""

from __future__ import annotations

import math

PHYSICAL_RANGES = {
    "R": (float, 1e-9, 1.0, False, False),
    "E_star": (float, 1e3, 1e13, False, False),
    "G_star": (float, 1e3, 1e13, False, False),
    "mu": (float, 1e-9, math.inf, False, True),
    "runner_mass": (float, 0.0, 1e6, False, False),
    "F_ext": (float, -1e6, 1e6, False, False),
    "N_min": (float, 0.0, 1e6, False, False),
    "N_max": (float, 1e-12, 1e6, False, False),
    "omega_R_max": (float, 1e-9, 1e3, False, False),
    "creep_max": (float, 1e-9, 2.0, False, False),
    "stroke_roll": (float, 1e-12, 1.0, False, False),
    "stroke_translate": (float, 1e-12, 1.0, False, False),
    "period": (float, 1e-12, 1e3, False, False),
}
