"""Noise-free calibration sessions with a known truth, for checking the estimators exactly.

The "physical" robot is the model itself (no kinematic error), the tools sit exactly at the
truth's transforms, every touch is exact and every annotation is the true pixel. A calibration
of such a session must return the truth to numerical precision. The digital twin (noise, robot
errors, planned poses) builds on this.

Geometry, in ``base_link``: the reference tips lie in front of the robot at about waist height;
tools approach them pointing forward and down, each trial from another direction. Image samples
sweep a 4×4 grid of pixels over the image for each of several probe poses that step the image
plane through the needle's workspace, so the needle tips fill a volume.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.data.session import Session, Touches
from brachycal.errors import SolverError
from brachycal.imaging.pixels import DEFAULT_IMAGE_SIZE_PX, DEFAULT_SPACING_M, image_points
from brachycal.model.ik import solve_ik
from brachycal.model.names import LEFT_ARM, NEEDLE_TIP, PROBE_TIP, READY, RIGHT_ARM, TOP_MODEL_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, transform_points

#: The arms' axes in a configuration (:data:`brachycal.model.names.LEFT_ARM`, ``RIGHT_ARM``).
LEFT, RIGHT = LEFT_ARM, RIGHT_ARM

#: The probe pose of the samples: shaft (z) along +x of base_link, image lateral (x) along +z.
R_BASE_PROBE = np.column_stack([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
P_BASE_PROBE = np.array([0.80, 0.10, 1.00])
#: Needle direction for the samples: the probe axis turned 35° about base z (wrists stay apart).
R_BASE_NEEDLE = Rotation.from_euler("z", 35.0, degrees=True).as_matrix() @ R_BASE_PROBE


@dataclass(frozen=True)
class SessionTruth:
    """The transforms a calibration must find, and the set-up it runs in (SI units).

    Attributes:
        T_ER_Ntip, T_EL_Ptip, T_Ptip_I: ``(4, 4)`` tool and image transforms.
        spacing_m: ``(2,)`` true pixel spacing (may differ from the scanner's nominal one).
        nominal_spacing_m: ``(2,)`` the spacing written into the session (what the scanner says).
        p_ER_Mtip: ``(3,)`` top-model tip on the right flange.
        p_R_Rtip1, p_R_Rtip2: ``(3,)`` the reference tips in ``base_link``.
        size_px: ``(2,)`` image width and height.
    """

    T_ER_Ntip: FloatArray
    T_EL_Ptip: FloatArray
    T_Ptip_I: FloatArray
    spacing_m: FloatArray
    nominal_spacing_m: FloatArray
    p_ER_Mtip: FloatArray
    p_R_Rtip1: FloatArray
    p_R_Rtip2: FloatArray
    size_px: np.ndarray

    def robot(self, nominal: Robot) -> Robot:
        """The model with the true tool frames: its FK is where the physical tools are."""
        robot = nominal.with_tool_transform(NEEDLE_TIP, self.T_ER_Ntip)
        robot = robot.with_tool_transform(PROBE_TIP, self.T_EL_Ptip)
        robot = robot.with_tool_transform(US_IMAGE, self.T_Ptip_I)
        return robot.with_tool_transform(TOP_MODEL_TIP, make_transform(np.eye(3), self.p_ER_Mtip))


def _nudge(T: FloatArray, rotvec: list[float], shift_m: list[float]) -> FloatArray:
    return T @ make_transform(Rotation.from_rotvec(rotvec).as_matrix(), shift_m)


def default_truth(robot: Robot, spacing_scale: tuple[float, float] = (1.0, 1.0)) -> SessionTruth:
    """The URDF's nominal frames moved by a few millimetres and a degree or two (fixed values).

    Args:
        robot: the nominal model.
        spacing_scale: true spacing = the nominal :data:`~brachycal.imaging.DEFAULT_SPACING_M`
            (0.19 mm/pixel) × this, per axis (e.g. 1.04 axially for water at room temperature).
    """
    nominal = np.array(DEFAULT_SPACING_M)
    return SessionTruth(
        T_ER_Ntip=_nudge(robot.tool_transform(NEEDLE_TIP)[1], [0.02, -0.015, 0.03], [1.5e-3, -2.0e-3, 3.0e-3]),
        T_EL_Ptip=_nudge(robot.tool_transform(PROBE_TIP)[1], [-0.01, 0.02, -0.025], [-2.0e-3, 1.0e-3, -1.5e-3]),
        T_Ptip_I=_nudge(robot.tool_transform(US_IMAGE)[1], [0.015, 0.01, -0.02], [2.5e-3, -1.5e-3, 1.0e-3]),
        spacing_m=nominal * np.asarray(spacing_scale),
        nominal_spacing_m=nominal,
        p_ER_Mtip=np.array([0.0, 0.0, 0.150]),
        p_R_Rtip1=np.array([0.75, -0.05, 0.85]),
        p_R_Rtip2=np.array([0.72, 0.08, 0.85]),
        size_px=np.array(DEFAULT_IMAGE_SIZE_PX),
    )


def _approach(k: int, n: int, turn_deg: float = 0.0) -> FloatArray:
    """Orientation of a tool approaching a tip, trial ``k`` of ``n``: z forward-down, varied."""
    base = Rotation.from_euler("y", 135.0, degrees=True)  # z axis points forward and down
    spin = Rotation.from_euler("z", 360.0 * k / n + turn_deg, degrees=True)
    tilt = Rotation.from_euler("x", 12.0, degrees=True)
    return (base * spin * tilt).as_matrix()


def touch(
    robot: Robot, frame: str, arm: list[int], p_R: FloatArray, k: int, n: int, q0: FloatArray, seed: int
) -> FloatArray:
    """Joints that put ``frame`` on ``p_R`` for trial ``k`` of ``n``.

    Like an operator, it turns the approach about the vertical when one direction is out of the
    arm's reach (up to ±60° in 20° steps).

    Raises:
        SolverError: no approach direction reaches the tip.
    """
    for turn in (0.0, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0):
        try:
            T = make_transform(_approach(k, n, turn), p_R)
            return solve_ik(robot, frame, T, q0, arm, margin=0.05, restarts=10, seed=seed)
        except SolverError:  # unreachable this way: turn the approach (input errors propagate)
            continue
    raise SolverError(
        f"{frame} cannot touch the reference tip at {np.round(p_R, 4).tolist()} m in base_link "
        f"(trial {k + 1} of {n}, approach turned up to ±60°)"
    )


#: The tools that touch the reference tips: session name, their frame, the arm's joints. The
#: needle and the probe also make the three-point axes moves.
TOUCH_TOOLS = (("top_model", TOP_MODEL_TIP, RIGHT), ("needle", NEEDLE_TIP, RIGHT), ("probe", PROBE_TIP, LEFT))

#: Where the three-point moves start, per tool: in front of the robot, each on its arm's side.
AXES_START = {"needle": np.array([0.70, -0.10, 0.95]), "probe": np.array([0.70, 0.15, 0.95])}


def axes_moves(
    robot: Robot, frame: str, arm: list[int], p1: FloatArray, q0: FloatArray, seed: int, move_m: float = 0.02
) -> dict[str, FloatArray]:
    """Joints at p1, p2 = p1 + move along the tool's y, p3 = p1 + move along its z (one orientation).

    The orientation is turned about the vertical (as in :func:`touch`) until all three points
    are reachable; p2 and p3 start from p1's joints so the arm stays in one posture.

    Raises:
        SolverError: no orientation makes all three points reachable.
    """
    for turn in (0.0, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0):
        R = _approach(0, 1, turn)
        try:
            q1 = solve_ik(robot, frame, make_transform(R, p1), q0, arm, margin=0.05, restarts=10, seed=seed)
            return {
                "p1": q1,
                "p2": solve_ik(
                    robot, frame, make_transform(R, p1 + move_m * R[:, 1]), q1, arm, margin=0.05, restarts=10, seed=seed
                ),
                "p3": solve_ik(
                    robot, frame, make_transform(R, p1 + move_m * R[:, 2]), q1, arm, margin=0.05, restarts=10, seed=seed
                ),
            }
        except SolverError:  # unreachable this way: turn the approach (input errors propagate)
            continue
    raise SolverError(
        f"{frame} cannot make the three-point moves ({move_m * 1e3:g} mm) from {np.round(p1, 4).tolist()} m "
        "in base_link (orientation turned up to ±60°)"
    )


def exact_session(
    robot: Robot,
    truth: SessionTruth,
    *,
    trials: int = 3,
    probe_poses: int = 4,
    grid: int = 4,
    seed: int = 0,
) -> Session:
    """A noise-free session: ``probe_poses × grid²`` image samples, ``trials`` touches per tip.

    Args:
        robot: the nominal model (its flanges are the physical robot's).
        truth: the transforms to hide in the data.
        trials: repeats per tool and reference tip.
        probe_poses: probe poses, each stepping the image plane ~5 mm along its normal.
        grid: pixels per image axis per probe pose.
        seed: seed of the IK restarts.

    Raises:
        SolverError: a pose of the set-up is unreachable.
    """
    physical = truth.robot(robot)
    q_home = READY.copy()
    ik = functools.partial(solve_ik, margin=0.05, restarts=50, seed=seed)

    touches = {}
    for reference, p_R in (("rtip1", truth.p_R_Rtip1), ("rtip2", truth.p_R_Rtip2)):
        for tool, frame, arm in TOUCH_TOOLS:
            q = np.array([touch(physical, frame, arm, p_R, k, trials, q_home, seed) for k in range(trials)])
            touches[tool, reference] = Touches(np.arange(1, trials + 1), q)

    axes = {
        tool: axes_moves(physical, frame, arm, AXES_START[tool], q_home, seed) for tool, frame, arm in TOUCH_TOOLS[1:]
    }

    width, height = truth.size_px
    us = np.linspace(0.3 * width, 0.75 * width, grid)
    vs = np.linspace(0.15 * height, 0.85 * height, grid)
    ids: list[str] = []
    configs: list[FloatArray] = []
    uv: list[tuple[float, float]] = []
    q = q_home.copy()
    for j in range(probe_poses):
        offset = (j - (probe_poses - 1) / 2) * 5e-3
        R_probe = Rotation.from_euler("x", 2.0 * (j - (probe_poses - 1) / 2), degrees=True).as_matrix()
        T_R_Ptip = make_transform(R_BASE_PROBE @ R_probe, P_BASE_PROBE + offset * R_BASE_PROBE[:, 1])
        q = ik(physical, PROBE_TIP, T_R_Ptip, q, LEFT)
        T_R_I = physical.fk(US_IMAGE, q)
        for u in us:
            for v in vs:
                p_R = transform_points(T_R_I, image_points((u, v), truth.spacing_m)[0])
                q = ik(physical, NEEDLE_TIP, make_transform(R_BASE_NEEDLE, p_R), q, RIGHT)
                ids.append(f"s{len(ids) + 1:03d}")
                configs.append(q.copy())
                uv.append((u, v))
    return Session(
        spacing_m=truth.nominal_spacing_m.copy(),
        size_px=truth.size_px.copy(),
        p_ER_Mtip=truth.p_ER_Mtip.copy(),
        touches=touches,
        axes=axes,
        sample_ids=ids,
        samples_q=np.array(configs),
        uv_px=np.array(uv),
        joint_names=robot.joint_names,
    )
