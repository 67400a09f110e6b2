"""Planning the calibration sample poses: the grid, dual-arm mink IK, Pinocchio/Coal checks, order.

:class:`PlanSpec` says what to plan (a cube of needle-tip targets in ``base_link``, metres; the
image geometry in pixels; the insertion direction); :func:`plan_poses` solves one dual-arm pose
per target (:class:`DualArmIK` with :class:`IKSettings`), checks each again
(:class:`PoseVerifier` with :class:`Thresholds`) and orders them by motion time, returning a
:class:`Plan`; :func:`write_plan` writes it as CSV (controller joint order, radians and degrees).
The robot's rig (``robot.rig``) gives the arms, the ready stance planning starts from, the collision
pairs, the controller order and the workspace (:meth:`PlanSpec.for_robot`); :data:`READY` is the
SDA10F's ready stance (:data:`brachycal.model.READY`).

Excitation poses (robot identification, ``plan excitation``): :func:`plan_excitation` chooses
extra touches and samples for a session whose robot was identified (:class:`ExcitationPlan` of
:class:`Candidate` poses), :func:`write_excitation` writes them.
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use: the plan's options need only the light spec module
    from brachycal.model.names import READY
    from brachycal.planning.dual_arm_ik import DualArmIK, IKSettings
    from brachycal.planning.excitation import Candidate, ExcitationPlan, plan_excitation, write_excitation
    from brachycal.planning.output import infeasible_path, write_infeasible, write_plan
    from brachycal.planning.plan import GridPoint, Infeasible, Plan, PlannedPose, grid_points, plan_poses
    from brachycal.planning.pose_checks import PoseCheck, PoseVerifier, Thresholds
    from brachycal.planning.spec import PlanSpec, RectFOV, SectorFOV

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "READY",
    "Candidate",
    "DualArmIK",
    "ExcitationPlan",
    "GridPoint",
    "IKSettings",
    "Infeasible",
    "Plan",
    "PlanSpec",
    "PlannedPose",
    "PoseCheck",
    "PoseVerifier",
    "RectFOV",
    "SectorFOV",
    "Thresholds",
    "grid_points",
    "infeasible_path",
    "plan_excitation",
    "plan_poses",
    "write_excitation",
    "write_infeasible",
    "write_plan",
]
