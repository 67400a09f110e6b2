"""Noise-free calibration sessions with a known truth, for checking the estimators exactly.

The "physical" robot is the model itself (no kinematic error), the tools sit exactly at the
truth's transforms, every touch is exact and every annotation is the true pixel. A calibration
of such a session must return the truth to numerical precision. The digital twin (noise, robot
errors, planned poses) builds on this.

Geometry, on any rig (:attr:`Robot.rig <brachycal.model.robot.Robot.rig>`): every place is an
offset from the rig's sample cube (``workspace.cube_centre_m``) in its *workspace frame*
(:func:`workspace_frame`: x forward, the probe's depth direction made horizontal; z up, the
base's z; the offsets' y towards the probe arm's side, :func:`probe_side`), so a robot
description places the whole session by its cube. The reference tips lie 0.2 m below the cube,
in front of the needle arm; tools approach them pointing forward and down, each trial from
another direction; the axes moves start 0.1 m
below and behind the cube, each on its arm's side. Image samples sweep a 4×4 grid of pixels over
the image for each of several probe poses that step the image plane through the needle's
workspace, so the needle tips fill a volume. Places are rounded to 1 µm, so a cube given in round
numbers gives round-number places: the SDA10F's (cube at (0.80, 0.10, 1.05) m) are exactly the
fixed ``base_link`` positions of earlier versions, which keeps its twin's files identical.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.data.session import Session, Touches
from brachycal.errors import InputError, SolverError
from brachycal.imaging.pixels import DEFAULT_IMAGE_SIZE_PX, DEFAULT_SPACING_M, image_points
from brachycal.model.ik import solve_ik
from brachycal.model.names import LEFT_ARM, NEEDLE_TIP, PROBE_TIP, RIGHT_ARM, TOP_MODEL_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, transform_points

#: The SDA10F's arms' axes in a configuration (:data:`brachycal.model.names.LEFT_ARM`, ``RIGHT_ARM``);
#: other robots: ``robot.rig.probe_arm_indices``, ``needle_arm_indices``.
LEFT, RIGHT = LEFT_ARM, RIGHT_ARM

#: Places of the session as offsets from the sample cube's centre in the workspace frame
#: (:func:`workspace_frame`: forward, towards the probe arm's side, up), metres. On the SDA10F
#: (cube at (0.80, 0.10, 1.05) m, workspace frame = base_link) they are the positions the twin has
#: always used: reference tips (0.75, -0.05, 0.85) and (0.72, 0.08, 0.85) m, axes-move starts
#: (0.70, -0.10, 0.95) m (needle) and (0.70, 0.15, 0.95) m (probe), sample probe at (0.80, 0.10, 1.00) m.
REFERENCE_TIP_OFFSETS_M: dict[str, tuple[float, float, float]] = {
    "rtip1": (-0.05, -0.15, -0.20),
    "rtip2": (-0.08, -0.02, -0.20),
}
AXES_START_OFFSETS_M: dict[str, tuple[float, float, float]] = {
    "needle": (-0.10, -0.20, -0.10),
    "probe": (-0.10, 0.05, -0.10),
}
SAMPLE_PROBE_OFFSET_M = (0.0, 0.0, -0.05)
#: Places are rounded to this grid, metres (see the module docstring).
PLACE_GRID_DECIMALS = 6


def workspace_frame(robot: Robot) -> FloatArray:
    """``R_base_ws (3, 3)``: the rig's workspace frame, a rotation, columns forward, left, up (in the
    base frame).

    Up is the base's z (the tips lie below the cube, tools approach downwards); forward is the
    probe's depth direction (``workspace.image_depth_dir``) made horizontal, or the needle's
    insertion direction if the probe points straight down; left is up × forward. Identity on the
    three bundled robots. Which side the probe arm is on is :func:`probe_side`.

    Raises:
        InputError: both directions are vertical (no forward direction).
    """
    rig = robot.rig
    up = np.array([0.0, 0.0, 1.0])
    for direction in (rig.workspace.image_depth_dir, rig.workspace.insertion_dir):
        forward = np.asarray(direction, dtype=float) - direction[2] * up
        if np.linalg.norm(forward) > 1e-6:
            forward = forward / np.linalg.norm(forward)
            break
    else:
        raise InputError(
            f"robot {rig.name!r}: the workspace's image depth and insertion directions are both vertical; "
            "the twin needs a forward direction",
            file=rig.source,
        )
    return np.column_stack([forward, np.cross(up, forward), up])


def probe_side(robot: Robot) -> float:
    """``+1`` when the probe arm stands to the left of the needle arm in :func:`workspace_frame`
    (their flanges at the ready stance; the bundled robots), ``-1`` when to the right: the offsets'
    side component (:data:`REFERENCE_TIP_OFFSETS_M`...) is multiplied by it, so that each place falls
    on the side of the arm that uses it whichever arm holds the needle. Orientations are not
    mirrored (a mirror is not a rotation)."""
    rig = robot.rig
    ready = rig.ready
    towards_probe = robot.fk(rig.probe_flange, ready)[:3, 3] - robot.fk(rig.needle_flange, ready)[:3, 3]
    return -1.0 if towards_probe @ workspace_frame(robot)[:, 1] < 0 else 1.0


def place(robot: Robot, offset_m: tuple[float, float, float]) -> FloatArray:
    """``(3,)`` the point ``offset_m`` (forward, towards the probe arm's side, up; metres) from the
    rig's cube centre, in the base frame, rounded to 1 µm (:data:`PLACE_GRID_DECIMALS`)."""
    centre = np.asarray(robot.rig.workspace.cube_centre_m, dtype=float)
    offset = np.asarray(offset_m, dtype=float) * np.array([1.0, probe_side(robot), 1.0])
    return np.round(centre + workspace_frame(robot) @ offset, PLACE_GRID_DECIMALS)


def reference_tips(robot: Robot) -> dict[str, FloatArray]:
    """The two reference tips, ``(3,)`` each in the base frame (:data:`REFERENCE_TIP_OFFSETS_M`)."""
    return {name: place(robot, offset) for name, offset in REFERENCE_TIP_OFFSETS_M.items()}


def axes_start(robot: Robot) -> dict[str, FloatArray]:
    """Where the three-point moves start, per tool (``needle``, ``probe``): ``(3,)`` in the base frame."""
    return {tool: place(robot, offset) for tool, offset in AXES_START_OFFSETS_M.items()}


def touch_tools(robot: Robot) -> tuple[tuple[str, str, list[int]], ...]:
    """The tools that touch the reference tips: session name, their frame, the arm's joint indices.
    The needle and the probe (the last two) also make the three-point axes moves."""
    rig = robot.rig
    return (
        ("top_model", TOP_MODEL_TIP, rig.needle_arm_indices),
        ("needle", NEEDLE_TIP, rig.needle_arm_indices),
        ("probe", PROBE_TIP, rig.probe_arm_indices),
    )


def sample_poses(robot: Robot) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The exact session's probe pose and needle orientation: ``R_base_probe (3, 3)``,
    ``p_base_probe (3,)`` and ``R_base_needle (3, 3)``.

    The probe's shaft (z) along the workspace's image depth direction, its image lateral (x) along
    the image lateral direction, 5 cm below the cube centre; the needle along the insertion
    direction with its x along the image lateral direction (wrists stay apart). On the SDA10F:
    probe along +x, image lateral +z, needle turned 35° about z.
    """
    ws = robot.rig.workspace
    depth = np.asarray(ws.image_depth_dir, dtype=float)
    lateral = np.asarray(ws.image_lateral_dir, dtype=float)
    R_probe = np.column_stack([lateral, np.cross(depth, lateral), depth])
    insertion = np.asarray(ws.insertion_dir, dtype=float)
    x = lateral - (lateral @ insertion) * insertion
    x = x / np.linalg.norm(x)
    R_needle = np.column_stack([x, np.cross(insertion, x), insertion])
    return R_probe, place(robot, SAMPLE_PROBE_OFFSET_M), R_needle


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
    """The description's nominal tool frames moved by a few millimetres and a degree or two (fixed
    values); the top model as mounted nominally; the reference tips of :func:`reference_tips`.

    Args:
        robot: the nominal model (with its rig).
        spacing_scale: true spacing = the nominal :data:`~brachycal.imaging.DEFAULT_SPACING_M`
            (0.19 mm/pixel) × this, per axis (e.g. 1.04 axially for water at room temperature).
    """
    nominal = np.array(DEFAULT_SPACING_M)
    tips = reference_tips(robot)
    return SessionTruth(
        T_ER_Ntip=_nudge(robot.tool_transform(NEEDLE_TIP)[1], [0.02, -0.015, 0.03], [1.5e-3, -2.0e-3, 3.0e-3]),
        T_EL_Ptip=_nudge(robot.tool_transform(PROBE_TIP)[1], [-0.01, 0.02, -0.025], [-2.0e-3, 1.0e-3, -1.5e-3]),
        T_Ptip_I=_nudge(robot.tool_transform(US_IMAGE)[1], [0.015, 0.01, -0.02], [2.5e-3, -1.5e-3, 1.0e-3]),
        spacing_m=nominal * np.asarray(spacing_scale),
        nominal_spacing_m=nominal,
        p_ER_Mtip=robot.tool_transform(TOP_MODEL_TIP)[1][:3, 3].copy(),
        p_R_Rtip1=tips["rtip1"],
        p_R_Rtip2=tips["rtip2"],
        size_px=np.array(DEFAULT_IMAGE_SIZE_PX),
    )


#: Turns of the approach an operator tries, in this order, when a direction is out of reach, degrees:
#: 20° steps both ways, up to half a turn. The SDA10F and Baxter reach every touch of the default
#: twin straight on (0°; the SDA10F's sessions are those of the earlier ±60° list); the UR5 cell's
#: probe needs 80° at one touch of seed 0 (its reference tips sit 0.1 m above the table).
TURNS_DEG = (0.0, *(sign * step for step in range(20, 181, 20) for sign in (1.0, -1.0)))[:-1]


def _approach(k: int, n: int, turn_deg: float = 0.0, R_base_ws: FloatArray | None = None) -> FloatArray:
    """Orientation of a tool approaching a tip, trial ``k`` of ``n``: z forward-down, varied
    (forward and down of the workspace frame ``R_base_ws``; default the base's axes)."""
    base = Rotation.from_euler("y", 135.0, degrees=True)  # z axis points forward and down
    spin = Rotation.from_euler("z", 360.0 * k / n + turn_deg, degrees=True)
    tilt = Rotation.from_euler("x", 12.0, degrees=True)
    R = (base * spin * tilt).as_matrix()
    return R if R_base_ws is None else R_base_ws @ R


def touch(
    robot: Robot, frame: str, arm: list[int], p_R: FloatArray, k: int, n: int, q0: FloatArray, seed: int
) -> FloatArray:
    """Joints that put ``frame`` on ``p_R`` for trial ``k`` of ``n``.

    Like an operator, it turns the approach about the vertical when one direction is out of the
    arm's reach (:data:`TURNS_DEG`: up to ±180° in 20° steps).

    Raises:
        SolverError: no approach direction reaches the tip.
    """
    R_base_ws = workspace_frame(robot)
    for turn in TURNS_DEG:
        try:
            T = make_transform(_approach(k, n, turn, R_base_ws), p_R)
            return solve_ik(robot, frame, T, q0, arm, margin=0.05, restarts=10, seed=seed)
        except SolverError:  # unreachable this way: turn the approach (input errors propagate)
            continue
    raise SolverError(
        f"{frame} cannot touch the reference tip at {np.round(p_R, 4).tolist()} m in the base frame "
        f"(trial {k + 1} of {n}, approach turned up to ±180°)"
    )


def axes_moves(
    robot: Robot, frame: str, arm: list[int], p1: FloatArray, q0: FloatArray, seed: int, move_m: float = 0.02
) -> dict[str, FloatArray]:
    """Joints at p1, p2 = p1 + move along the tool's y, p3 = p1 + move along its z (one orientation).

    The orientation is turned about the vertical (as in :func:`touch`) until all three points
    are reachable; p2 and p3 start from p1's joints so the arm stays in one posture.

    Raises:
        SolverError: no orientation makes all three points reachable.
    """
    R_base_ws = workspace_frame(robot)
    for turn in TURNS_DEG:
        R = _approach(0, 1, turn, R_base_ws)
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
        "in the base frame (orientation turned up to ±180°)"
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
        robot: the nominal model with its rig (its flanges are the physical robot's).
        truth: the transforms to hide in the data.
        trials: repeats per tool and reference tip.
        probe_poses: probe poses, each stepping the image plane ~5 mm along its normal.
        grid: pixels per image axis per probe pose.
        seed: seed of the IK restarts.

    Raises:
        SolverError: a pose of the set-up is unreachable.
    """
    physical = truth.robot(robot)
    q_home = robot.rig.ready
    needle_arm, probe_arm = robot.rig.needle_arm_indices, robot.rig.probe_arm_indices
    ik = functools.partial(solve_ik, margin=0.05, restarts=50, seed=seed)
    tools = touch_tools(robot)

    touches = {}
    for reference, p_R in (("rtip1", truth.p_R_Rtip1), ("rtip2", truth.p_R_Rtip2)):
        for tool, frame, arm in tools:
            q = np.array([touch(physical, frame, arm, p_R, k, trials, q_home, seed) for k in range(trials)])
            touches[tool, reference] = Touches(np.arange(1, trials + 1), q)

    starts = axes_start(robot)
    axes = {tool: axes_moves(physical, frame, arm, starts[tool], q_home, seed) for tool, frame, arm in tools[1:]}
    R_base_probe, p_base_probe, R_base_needle = sample_poses(robot)

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
        T_R_Ptip = make_transform(R_base_probe @ R_probe, p_base_probe + offset * R_base_probe[:, 1])
        q = ik(physical, PROBE_TIP, T_R_Ptip, q, probe_arm)
        T_R_I = physical.fk(US_IMAGE, q)
        for u in us:
            for v in vs:
                p_R = transform_points(T_R_I, image_points((u, v), truth.spacing_m)[0])
                q = ik(physical, NEEDLE_TIP, make_transform(R_base_needle, p_R), q, needle_arm)
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
