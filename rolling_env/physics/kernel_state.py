"""What the kernel's state and work arrays say, read alike for one ``Drive`` and for the
batched core: the error flags of a state (``check_flags``) and named views of the cell rows
(``CellViews``)."""

from __future__ import annotations

import numpy as np

from rolling_env.physics import _kernel as K

SLIDE_MESSAGE = (
    "the massless runner (m = 0) has no force equilibrium: |F_ext| exceeds the "
    "largest force the contact holds (mu N with finite friction, 0 without contact)"
    "; the runner would accelerate without bound.  Give it a finite mass m > 0, or "
    "keep |F_ext| below mu N with the contact closed"
)


def check_flags(st) -> None:
    """Raise for the kernel's error flags in a state vector or a batch of them (rows):
    the grid flag (RuntimeError), a massless runner without force equilibrium (ValueError,
    ``SLIDE_MESSAGE``) and a non-finite value (FloatingPointError)."""
    flags = np.bitwise_or.reduce(np.atleast_2d(st)[:, K.ST_FLAG].astype(np.int64))
    if flags & K.FLAG_SLIDE:
        raise ValueError(SLIDE_MESSAGE)
    if flags & K.FLAG_GRID:
        raise RuntimeError(
            "the contact left the spring row: the rolling stroke exceeded the "
            "grid built for it (enlarge `stroke`)"
        )
    if flags & K.FLAG_NONFINITE:
        raise FloatingPointError(
            "the kernel produced a non-finite value (it overflowed the "
            "float range: reduce dt_tick, the rates or the load)"
        )


class CellViews:
    """Named read-only views of the cell work array ``self.cells`` (rows ``K.W_*`` on the
    second-to-last axis, so one drive's (rows, n) and a batch's (envs, rows, n) alike)."""

    @property
    def U(self) -> np.ndarray:
        """Tangential content of each cell (G* = 1 units)."""
        return self.cells[..., K.W_U, :]

    @property
    def A(self) -> np.ndarray:
        return self.cells[..., K.W_A, :]

    @property
    def B(self) -> np.ndarray:
        return self.cells[..., K.W_B, :]

    @property
    def L(self) -> np.ndarray:
        """Friction work rows (``K.L_*``); none (0 rows) with infinite friction."""
        return self.cells[..., K.W_L :, :]
