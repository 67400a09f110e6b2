"""The dual-arm session as a :class:`~brachycal.calibration.robot.arm_fit.ResidualModel`: the
whole chain's residuals (touches, axes moves, image samples; :func:`chain_residuals`) with the
chain's own parameters (the tools, the image calibration) as the protocol's unknowns ``y``, and
the joint-origin Jacobian of :func:`robot_jacobian_at`. With it :func:`fit_arm` identifies the
dual-arm rig as it does an arm from touches or a tracker (:func:`session_arm_fit`).

The session's production estimator stays :func:`~brachycal.calibration.robot.identification.identify_robot`
(outlier flags settled on the corrected robot, the chain's checked final fit and its noise rule
for the axes moves); :func:`session_arm_fit` reproduces its corrections to a few hundredths of
their posterior SD (tests/test_session_protocol.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brachycal.calibration.chain import ChainData, ParameterLayout, chain_jacobian, chain_residuals, robot_jacobian_at
from brachycal.calibration.robot.arm_fit import ArmFit, Evaluation, ParameterSelection, fit_arm
from brachycal.calibration.robot.identification import chain_start
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Noise groups. The axes moves' few rows share the touches' level (the chain's rule when they
#: have too few degrees of freedom for their own: ~6 rows), here by pooling them with the touches.
SESSION_GROUPS = ("touch", "image")
#: A step in a chain parameter below this (metres, radians, relative spacing) is nothing worth noticing.
CHAIN_STEP = 1e-3


@dataclass(frozen=True)
class SessionResiduals:
    """The session's residuals (metres, unnormalised) on a robot at the chain parameters ``y``.

    Attributes:
        session: the recorded data.
        layout: the chain's parameters (the image model's).
        base: the layout's linearisation point (``y`` is a step from it).
        keep: ``(N,)`` the image samples in the fit.
        size: the number of chain parameters.
    """

    session: Session
    layout: ParameterLayout
    base: dict[str, FloatArray]
    keep: np.ndarray
    size: int

    @property
    def groups(self) -> tuple[str, ...]:
        return SESSION_GROUPS

    def y_scale(self) -> FloatArray:
        return np.full(self.size, CHAIN_STEP)

    def evaluate(self, robot: Robot, y: FloatArray) -> Evaluation:
        data = ChainData.of(self.session, robot)
        unit = {"touch": 1.0, "axes": 1.0, "image": 1.0}
        r = chain_residuals(y, self.layout, data, self.base, unit, self.keep)
        J_y = chain_jacobian(y, self.layout, data, self.base, unit, self.keep)
        J_c = robot_jacobian_at(self.session, robot, self.layout, y, self.base, unit, self.keep)
        rows = data.group_rows(int(self.keep.sum()))
        group = np.zeros(len(r), dtype=int)  # touches and axes moves: group 0
        group[rows["image"]] = SESSION_GROUPS.index("image")
        return Evaluation(r, J_c, J_y, group)


def session_arm_fit(
    session: Session, robot: Robot, initial: SequentialResult, model: str, accuracy: RobotAccuracy
) -> ArmFit:
    """The dual-arm rig identified by :func:`fit_arm` from its session: every joint origin free
    with ``accuracy`` its prior, the chain (image ``model``) its unknowns, started from the chain
    solved on the nominal robot (outliers it flags left out), the noise levels re-estimated.

    Raises:
        DegenerateDataError: the session does not determine the chain.
    """
    use = np.ones(len(session.uv_px), dtype=bool)
    first = chain_start(session, robot, initial, model, use, rounds=2)
    residuals = SessionResiduals(session, first.layout, first.base, use & ~first.outliers, len(first.x))
    selection = ParameterSelection(tuple(robot.joint_names), np.ones((robot.nq, 6), dtype=bool))
    sigma = {"touch": first.sigma["touch"], "image": first.sigma["image"]}
    return fit_arm(robot, residuals, first.x.copy(), selection, sigma, accuracy, estimate_noise=SESSION_GROUPS)
