"""One chain least-squares problem: its data, layout and starting rotations, and the solve.

:class:`ChainProblem` is what the stages of :func:`~brachycal.calibration.chain.fit.fit_chain`
share: normalised residuals (with the joint offsets' prior rows when they are estimated), their
Jacobian, one least-squares solve (:func:`~brachycal.calibration.least_squares.solve_least_squares`),
and the image samples it flags.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from brachycal.calibration.chain.data import ChainData
from brachycal.calibration.chain.jacobian import chain_jacobian
from brachycal.calibration.chain.layout import ParameterLayout, Unpacked
from brachycal.calibration.chain.residuals import chain_residuals, image_residuals
from brachycal.calibration.least_squares import Solution, solve_least_squares
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Image samples whose 3D residual exceeds this many ``√3 σ_image`` are flagged as gross errors
#: (module docstring of :mod:`brachycal.calibration.chain`: a clean sample passes it with
#: probability 5e-8, a 15 px annotation mistake sits at about 8).
OUTLIER_THRESHOLD = 3.5
#: Prior SD of an estimated joint zero offset (rad): keeps weakly excited offsets near zero.
OFFSET_PRIOR_SD = np.radians(0.01)
#: Forward-difference step of the joint offsets' Jacobian columns (rad): rounding and curvature
#: both stay below 1e-7 of the derivative.
OFFSET_STEP = 1e-7


#: Normalised residuals ``(M,)`` and their Jacobian ``(M, P)`` at some ``x``, with the noise levels
#: (metres per coordinate, per group) they were normalised by.
Reweighted = tuple[FloatArray, FloatArray, dict[str, float]]


@dataclass(frozen=True)
class ChainProblem:
    """The fixed parts of one chain problem.

    Attributes:
        session, robot: the recorded data and the model giving flange poses.
        data: the flange poses at zero joint offsets.
        layout: where each unknown sits in ``x``.
        base: the starting rotations that ``x``'s rotation vectors are about.
    """

    session: Session
    robot: Robot
    data: ChainData
    layout: ParameterLayout
    base: dict[str, FloatArray]
    _kept: dict[bytes, ChainData] = field(default_factory=dict, repr=False, compare=False)
    _unpacked: list[tuple[bytes, Unpacked]] = field(default_factory=list, repr=False, compare=False)

    @classmethod
    def start(
        cls, session: Session, robot: Robot, initial: SequentialResult, layout: ParameterLayout
    ) -> tuple[ChainProblem, FloatArray]:
        """The problem and its starting point ``x (P,)`` from the sequential result ``initial``."""
        data = ChainData.of(session, robot)
        x, base = layout.start(initial, data.spacing_m)
        return cls(session, robot, data, layout, base), x

    @property
    def estimates_offsets(self) -> bool:
        return bool(self.layout.offset_joints)

    def data_at(self, x: FloatArray) -> ChainData:
        """The flange poses with ``x``'s joint offsets (the fixed ones when none are estimated)."""
        if not self.estimates_offsets:
            return self.data
        return ChainData.of(self.session, self.robot, self.layout.offsets(x, self.robot.nq))

    def kept(self, keep: np.ndarray) -> ChainData:
        """The data with only the image samples ``keep`` (computed once per set of samples: a solve
        evaluates the residuals tens of times on the same samples)."""
        key = np.asarray(keep, dtype=bool).tobytes()
        if key not in self._kept:
            self._kept[key] = self.data.subset(np.asarray(keep, dtype=bool))
        return self._kept[key]

    def unpack(self, x: FloatArray) -> Unpacked:
        """:meth:`ParameterLayout.unpack` at ``x (P,)`` about :attr:`base` (read only). The last ``x``'s is
        kept: the solver evaluates the Jacobian where it has just evaluated the residuals."""
        key = np.asarray(x, dtype=float).tobytes()
        if self._unpacked and self._unpacked[0][0] == key:
            return self._unpacked[0][1]
        unpacked = self.layout.unpack(x, self.base, self.data.spacing_m)
        for array in unpacked[:4]:  # new arrays (the spacing may be the session's own: left as it is)
            array.flags.writeable = False
        self._unpacked[:] = [(key, unpacked)]
        return unpacked

    def residuals(self, x: FloatArray, sigma: dict[str, float], keep: np.ndarray) -> FloatArray:
        """Normalised residuals (:func:`chain_residuals`), then the joint offsets' prior rows."""
        if not self.estimates_offsets:
            kept = self.kept(keep)
            everything = np.ones(len(kept.uv_px), dtype=bool)
            return chain_residuals(x, self.layout, kept, self.base, sigma, everything, unpacked=self.unpack(x))
        r = chain_residuals(x, self.layout, self.data_at(x), self.base, sigma, keep)
        return np.concatenate([r, x[self.layout.blocks()["joint_offsets"]] / OFFSET_PRIOR_SD])

    def jacobian(self, x: FloatArray, sigma: dict[str, float], keep: np.ndarray) -> FloatArray:
        """Jacobian of :meth:`residuals`: analytic, the joint offsets' columns by forward differences
        (they move the flange poses)."""
        if not self.estimates_offsets:
            kept = self.kept(keep)
            everything = np.ones(len(kept.uv_px), dtype=bool)
            return chain_jacobian(x, self.layout, kept, self.base, sigma, everything, unpacked=self.unpack(x))
        at = self.data_at(x)
        J = chain_jacobian(x, self.layout, at, self.base, sigma, keep)  # zero in the joint offsets' columns
        offsets = self.layout.blocks()["joint_offsets"]
        r0 = chain_residuals(x, self.layout, at, self.base, sigma, keep)
        for column in range(offsets.start, offsets.stop):
            shifted = x.copy()
            shifted[column] += OFFSET_STEP
            moved = chain_residuals(shifted, self.layout, self.data_at(shifted), self.base, sigma, keep)
            J[:, column] = (moved - r0) / OFFSET_STEP
        prior = np.zeros((len(self.layout.offset_joints), len(x)))
        prior[:, offsets] = np.eye(len(self.layout.offset_joints)) / OFFSET_PRIOR_SD
        return np.vstack([J, prior])

    def solve(
        self,
        x: FloatArray,
        sigma: dict[str, float],
        keep: np.ndarray,
        loss: str,
        tol: float = 1e-10,
        at: Reweighted | None = None,
    ) -> Solution:
        """One least-squares solve from ``x`` with noise levels ``sigma`` on the image samples ``keep``;
        ``loss`` ``"soft_l1"`` (robust) or ``"linear"``; converged to ``tol`` (SciPy's ``xtol``, ``ftol``,
        ``gtol``: :func:`~brachycal.calibration.least_squares.solve_least_squares`).

        ``at``: the normalised residuals and Jacobian already evaluated at ``x`` (same samples) with
        other noise levels ``(fun, jac, sigma_at)``: a group's rows scale by ``sigma_at / sigma``, so
        the solve starts from them instead of evaluating both again (the noise levels' settling)."""
        start = None
        if at is not None:
            fun, jac, sigma_at = at
            ratio = np.ones(len(fun))
            for g, part in self.data.group_rows(int(np.count_nonzero(keep))).items():
                ratio[part] = sigma_at[g] / sigma[g]
            start = (fun * ratio, jac * ratio[:, None])
        return solve_least_squares(
            lambda x: self.residuals(x, sigma, keep),
            lambda x: self.jacobian(x, sigma, keep),
            x,
            loss,
            tol,
            start=start,
        )

    def image_residuals(self, x: FloatArray) -> FloatArray:
        """``(N, 3)`` every sample's image residual at ``x``, metres."""
        T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = self.unpack(x)
        return image_residuals(self.data_at(x), T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)

    def flagged(self, x: FloatArray, sigma: dict[str, float]) -> np.ndarray:
        """``(N,)`` samples whose 3D image residual exceeds :data:`OUTLIER_THRESHOLD` × √3 σ_image."""
        return np.linalg.norm(self.image_residuals(x), axis=1) / (np.sqrt(3.0) * sigma["image"]) > OUTLIER_THRESHOLD
