"""Accuracy figures of the paper, eqs. (10)–(12) with the errata of ``docs/conventions.md``.

For per-sample errors ``e_i = ‖P_real(i) − P_cal(i)‖``: MAE = mean(e), RMSE = sqrt(mean(e²)),
SD = population standard deviation of e (so RMSE² = MAE² + SD², as every row of the paper's
tables satisfies), max = max(e). Inside: metres; the ``*_mm`` names are millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.se3 import FloatArray


@dataclass(frozen=True)
class ErrorStats:
    """Error magnitudes ``(N,)`` in metres and their summary."""

    errors_m: FloatArray

    @classmethod
    def between(cls, p_real: ArrayLike, p_cal: ArrayLike) -> ErrorStats:
        """Statistics of ``‖p_real − p_cal‖`` for points ``(N, 3)`` in one frame, metres."""
        diff = np.asarray(p_real, dtype=float) - np.asarray(p_cal, dtype=float)
        return cls(np.linalg.norm(diff.reshape(-1, 3), axis=1))

    @property
    def n(self) -> int:
        return int(self.errors_m.size)

    @property
    def mae_mm(self) -> float:
        return float(np.mean(self.errors_m) * 1e3)

    @property
    def rmse_mm(self) -> float:
        return float(np.sqrt(np.mean(self.errors_m**2)) * 1e3)

    @property
    def sd_mm(self) -> float:
        return float(np.std(self.errors_m) * 1e3)

    @property
    def max_mm(self) -> float:
        return float(np.max(self.errors_m) * 1e3)

    def as_dict(self, with_errors: bool = False) -> dict[str, object]:
        out: dict[str, object] = {
            "n": self.n,
            "mae_mm": self.mae_mm,
            "rmse_mm": self.rmse_mm,
            "sd_mm": self.sd_mm,
            "max_mm": self.max_mm,
        }
        if with_errors:
            out["errors_mm"] = (self.errors_m * 1e3).tolist()
        return out
