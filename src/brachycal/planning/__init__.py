"""Planning the calibration sample poses (mink IK, Pinocchio checks, visiting order)."""

from brachycal.planning.dual_arm_ik import READY, DualArmIK, IKSettings
from brachycal.planning.plan import GridPoint, Infeasible, Plan, PlannedPose, grid_points, plan_poses
from brachycal.planning.spec import PlanSpec, RectFOV, SectorFOV
from brachycal.planning.verify import PoseCheck, PoseVerifier, Thresholds

__all__ = [
    "READY",
    "DualArmIK",
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
    "plan_poses",
]
