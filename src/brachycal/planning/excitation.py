"""Excitation poses: extra touches and image samples that identify the robot where the session does not.

Candidates (:func:`candidates`), each a configuration the robot model reaches within its limits and
clear of collisions (checked again here with :mod:`brachycal.planning.pose_checks`'s thresholds):

- **touches** of the session's reference tips (their positions as the calibration estimated them)
  by the needle and the probe, from new approach directions (the tool turned about the vertical by
  ±45° and tilted ±15° from the session's first trial) and, when the rig has shared joints (the
  SDA10F's torso), with the torso turned ±10°: the arm then reaches the same point in another
  posture. Only the tools mounted while imaging (no tool change; the top model is not used).
- **samples**: the same needle-tip pixel of a session sample reached with the arms in other
  configurations: either arm's elbow swivelled ±20° (the null space of a 7-axis arm: its flange
  stays where it was, so the tip shows at the same pixel) and the shared joints turned ±10° (both
  arms move together; the closed loop between them does not see the torso, so such a sample only
  repeats its source — the criterion scores it so).

Costs (minutes): an image sample :data:`~brachycal.planning.robot_time.SECONDS_PER_SAMPLE` (move,
image, annotate), a touch :data:`TOUCH_SECONDS` (jogging a tool tip onto a reference tip by hand:
the paper's 5-minute mechanical part is 18 touches and 6 axes points, ~12 s each done in one flow;
a touch on its own, with the approach to set up, is taken at 30 s), each plus the motion from its
source pose and back at a quarter of the vendor's speed (:data:`~brachycal.planning.robot_time.SPEED_SCALE`).
The chosen poses' total is then the ordered tour's (:func:`tour_minutes`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.chain import ChainFit
from brachycal.calibration.robot.identification import IdentificationResult
from brachycal.calibration.robot.observability import (
    SAMPLE,
    TOUCH,
    Observation,
    base_criterion,
    greedy,
    observation_rows,
    resolution,
)
from brachycal.data.session import Session
from brachycal.errors import SolverError
from brachycal.io import atomic_open
from brachycal.model.collision import ClearanceChecker, collision_link_pairs
from brachycal.model.ik import solve_ik
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, TOP_MODEL_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.planning import order as ordering
from brachycal.planning.pose_checks import Thresholds
from brachycal.planning.robot_time import DEFAULT_BUDGET_MINUTES, MAX_BUDGET_MINUTES, SECONDS_PER_SAMPLE, SPEED_SCALE
from brachycal.se3 import FloatArray, make_transform
from brachycal.validate import check_range

#: Whether excitation touches are offered by default: no. A session's ``touches.csv`` holds the
#: same trials for every tool at a reference tip (Table I pairs them by trial), so an extra needle
#: or probe touch cannot be recorded in it yet; the criterion picked at most one touch per session
#: when offered them (twin seeds 0–5), so samples alone lose little. In memory they work
#: (``touches=True``).
TOUCHES_RECORDABLE = False
#: A touch's dwell, seconds (module docstring).
TOUCH_SECONDS = 30.0
#: Elbow swivel of the sample variants, radians of the arm's most redundant joint.
SWIVEL_RAD = float(np.radians(20.0))
#: Shared-joint (torso) turn of the variants, radians: within the held-out range of the twin's
#: targeting and well inside the SDA10F torso's ±170°.
SHARED_TURN_RAD = float(np.radians(10.0))
#: Approach variants of a touch: turn about the vertical and tilt, degrees.
APPROACH_TURNS_DEG = (-45.0, 0.0, 45.0)
APPROACH_TILTS_DEG = (-15.0, 0.0, 15.0)


@dataclass(frozen=True)
class Candidate:
    """A reachable extra observation and how it was made.

    Attributes:
        observation: what would be recorded (its ``q (nq,)`` the commanded joints, radians).
        source_q: ``(nq,)`` the session pose it varies.
        variant: e.g. ``"needle arm swivel +20°"``, ``"approach turn 45° tilt -15°, shared +10°"``.
        label: ``"needle@rtip1"`` for a touch, the source sample's name for a sample.
        seconds: dwell plus the round trip from the source pose (module docstring).
        joint_margin_rad: smallest distance of a joint to its limits.
        clearance_m: smallest distance between checked link pairs.
        error_m: how far the tool tip is from where it should be (the IK's residual).
        target_m: ``(3,)`` where the tool tip should be, ``base_link`` metres (the reference tip as
            calibrated for a touch, the needle tip for a sample).
    """

    observation: Observation
    source_q: FloatArray
    variant: str
    label: str
    seconds: float
    joint_margin_rad: float
    clearance_m: float
    error_m: float
    target_m: FloatArray

    @property
    def minutes(self) -> float:
        return self.seconds / 60.0


def software_robot(corrected: Robot, fit: ChainFit, p_ER_Mtip: FloatArray) -> Robot:
    """The robot the software would command: the identified geometry with the calibrated tools."""
    robot = corrected.with_tool_transform(NEEDLE_TIP, fit.T_ER_Ntip)
    robot = robot.with_tool_transform(PROBE_TIP, fit.T_EL_Ptip)
    robot = robot.with_tool_transform(US_IMAGE, fit.image.T_Ptip_I)
    return robot.with_tool_transform(TOP_MODEL_TIP, make_transform(np.eye(3), p_ER_Mtip))


class _Checks:
    """Joint margins and clearances with the independent check's thresholds."""

    def __init__(self, robot: Robot, thresholds: Thresholds) -> None:
        self.robot, self.thresholds = robot, thresholds
        self.checker = ClearanceChecker(robot, collision_link_pairs(robot))

    def figures(self, q: FloatArray) -> tuple[float, float] | None:
        margin = float(np.min(np.minimum(q - self.robot.lower, self.robot.upper - q)))
        if not margin >= self.thresholds.joint_margin_rad:
            return None
        clearance = float(np.min(self.checker.distances(q)))
        if not clearance >= self.thresholds.collision_margin_m:
            return None
        return margin, clearance


def _null_space_joint(robot: Robot, flange: str, q: FloatArray, arm: list[int]) -> tuple[FloatArray, int] | None:
    """The arm's self-motion direction ``(len(arm),)`` at ``q`` (flange fixed) and its largest joint,
    or None for an arm without redundancy (6 axes or fewer)."""
    if len(arm) <= 6:
        return None
    h = 1e-7
    T0 = robot.fk(flange, q)
    J = np.empty((6, len(arm)))
    for k, j in enumerate(arm):
        dq = q.copy()
        dq[j] += h
        T = robot.fk(flange, dq)
        J[:3, k] = (T[:3, 3] - T0[:3, 3]) / h
        J[3:, k] = Rotation.from_matrix(T[:3, :3] @ T0[:3, :3].T).as_rotvec() / h
    n = np.linalg.svd(J)[2][-1]
    return n / np.max(np.abs(n)), int(np.argmax(np.abs(n)))


def _swivel(robot: Robot, flange: str, q: FloatArray, arm: list[int], angle: float) -> FloatArray | None:
    """``q`` with the arm swivelled by ``angle`` on its most redundant joint, its flange held."""
    found = _null_space_joint(robot, flange, q, arm)
    if found is None:
        return None
    direction, k = found
    start = q.copy()
    start[arm] += angle * direction * np.sign(direction[k])
    rest = [j for i, j in enumerate(arm) if i != k]
    try:
        return solve_ik(robot, flange, robot.fk(flange, q), start, rest, margin=0.05, restarts=0)
    except SolverError:
        return None


def candidates(
    robot: Robot,
    session: Session,
    rtips_m: FloatArray,
    spacing_m: FloatArray,
    *,
    thresholds: Thresholds = Thresholds(),
    samples: Sequence[int] | None = None,
    touches: bool = False,
) -> list[Candidate]:
    """Every reachable, collision-free excitation candidate (module docstring).

    Args:
        robot: the software's robot (:func:`software_robot`: identified geometry, calibrated tools).
        session: the recorded session whose poses are varied.
        rtips_m: ``(2, 3)`` the reference tips ``rtip1``, ``rtip2`` in ``base_link`` (the fit's estimate).
        spacing_m: ``(2,)`` the calibrated pixel spacing: a sample candidate's pixel is where the
            software's robot shows its source pose's needle tip (the annotated pixel carries noise).
        thresholds: the joint margin and clearance every candidate keeps (and the IK residual).
        samples: which session samples to vary (default all).
        touches: also touches (:data:`TOUCHES_RECORDABLE`: a session cannot hold them yet).
    """
    rig = robot.rig
    checks = _Checks(robot, thresholds)
    shared = rig.shared_indices
    turns = [0.0, SHARED_TURN_RAD, -SHARED_TURN_RAD] if shared else [0.0]

    def seconds(dwell: float, q: FloatArray, source: FloatArray) -> float:
        return dwell + 2.0 * float(ordering.move_times(np.array([q, source]), robot.velocity_limit, SPEED_SCALE)[0, 1])

    def turn_label(turn: float) -> str:
        return f", shared {np.degrees(turn):+.0f}°" if turn else ""

    out: list[Candidate] = []
    # Touches: the needle on the needle arm, the probe on the probe arm.
    for tool, frame, arm in (
        ("needle", NEEDLE_TIP, rig.needle_arm_indices),
        ("probe", PROBE_TIP, rig.probe_arm_indices),
    )[: 2 if touches else 0]:
        for k, reference in enumerate(("rtip1", "rtip2")):
            source = session.touches[tool, reference].q[0]
            R0 = robot.fk(frame, source)[:3, :3]
            for turn in turns:
                for spin in APPROACH_TURNS_DEG:
                    for tilt in APPROACH_TILTS_DEG:
                        if spin == tilt == 0.0 and not turn:
                            continue  # the session's own approach
                        R = Rotation.from_euler("zy", [spin, tilt], degrees=True).as_matrix() @ R0
                        start = source.copy()
                        start[shared] += turn
                        try:
                            q = solve_ik(
                                robot, frame, make_transform(R, rtips_m[k]), start, arm, margin=0.05, restarts=3
                            )
                        except SolverError:
                            continue
                        error = float(np.linalg.norm(robot.fk(frame, q)[:3, 3] - rtips_m[k]))
                        figures = checks.figures(q)
                        if figures is None or not error <= thresholds.position_m:
                            continue
                        out.append(
                            Candidate(
                                Observation(TOUCH, q, tool=tool, reference=reference),
                                source,
                                f"approach turn {spin:+.0f}° tilt {tilt:+.0f}°{turn_label(turn)}",
                                f"{tool}@{reference}",
                                seconds(TOUCH_SECONDS, q, source),
                                *figures,
                                error,
                                rtips_m[k].copy(),
                            )
                        )
    # Samples: the same pixel with the arms in other configurations.
    which = range(len(session.uv_px)) if samples is None else samples
    for i in which:
        source = session.samples_q[i]
        tip = robot.fk(NEEDLE_TIP, source)[:3, 3]
        T_I0 = robot.fk(US_IMAGE, source)
        p_I = np.linalg.solve(T_I0, np.append(tip, 1.0))[:3]
        uv = p_I[:2] / np.asarray(spacing_m, dtype=float)
        variants: list[tuple[str, FloatArray | None]] = []
        for name, flange, arm in (
            ("needle arm", rig.needle_flange, rig.needle_arm_indices),
            ("probe arm", rig.probe_flange, rig.probe_arm_indices),
        ):
            for sign in (1.0, -1.0):
                variants.append(
                    (
                        f"{name} swivel {sign * np.degrees(SWIVEL_RAD):+.0f}°",
                        _swivel(robot, flange, source, arm, sign * SWIVEL_RAD),
                    )
                )
        for turn in turns[1:]:
            turned = source.copy()
            turned[shared] += turn
            variants.append((turn_label(turn)[2:], turned))
        for variant, found in variants:
            if found is None:
                continue
            q = found
            # The needle tip where it was relative to the image: the same pixel.
            T_I = robot.fk(US_IMAGE, q)
            error = float(np.linalg.norm(robot.fk(NEEDLE_TIP, q)[:3, 3] - (T_I[:3, :3] @ p_I + T_I[:3, 3])))
            figures = checks.figures(q)
            if figures is None or not error <= thresholds.position_m:
                continue
            out.append(
                Candidate(
                    Observation(SAMPLE, q, uv_px=uv.copy()),
                    source,
                    variant,
                    session.sample_ids[i],
                    seconds(SECONDS_PER_SAMPLE, q, source),
                    *figures,
                    error,
                    robot.fk(NEEDLE_TIP, q)[:3, 3],
                )
            )
    return out


def tour(robot: Robot, chosen: Sequence[Candidate]) -> tuple[np.ndarray, FloatArray, float]:
    """The visiting order of ``chosen`` from the rig's ready stance (nearest neighbour + 2-opt at a
    quarter of the vendor's speed), each pose's move time from the previous one (s), and the minutes
    to record them all and return to the ready stance (dwells plus motion)."""
    if not chosen:
        return np.zeros(0, dtype=int), np.zeros(0), 0.0
    ready = robot.rig.ready
    Q = np.array([ready, *(c.observation.q for c in chosen)])
    times = ordering.move_times(Q, robot.velocity_limit, SPEED_SCALE)
    visit = ordering.nearest_neighbour_two_opt(times, start=0)
    moves = times[np.concatenate([[0], visit[:-1]]), visit]
    motion = float(moves.sum() + times[visit[-1], 0])
    dwell = sum(TOUCH_SECONDS if c.observation.kind == TOUCH else SECONDS_PER_SAMPLE for c in chosen)
    return visit - 1, moves, (dwell + motion) / 60.0


def tour_minutes(robot: Robot, chosen: Sequence[Candidate]) -> float:
    """Minutes to record ``chosen`` (:func:`tour`)."""
    return tour(robot, chosen)[2]


#: Smallest relative fall of the predicted RMS landing error worth robot time, whatever the prediction
#: can resolve: with noise-free data (a simulation) the resolution tends to zero, and 1 % of a
#: ~0.07 mm error (under a micrometre) is below anything a lab could measure.
MIN_IMPROVEMENT = 0.01


@dataclass(frozen=True)
class ExcitationPlan:
    """The chosen excitation poses and the criterion's figures.

    Attributes:
        chosen: in the greedy choice's order, best gain per minute first (:func:`write_excitation`
            writes them in visiting order, :func:`tour`).
        rms_before_mm: predicted RMS landing error of the session alone (mm).
        rms_after_mm: with the chosen poses (mm; equal to before when nothing is chosen).
        resolution: relative SD of the predicted RMS (:func:`~brachycal.calibration.robot.observability.resolution`).
        minutes: the chosen poses' robot time (:func:`tour_minutes`).
        budget_minutes: the budget they were chosen under.
        minimum_improvement: the relative fall judged worth recording.
        best_rms_mm: the predicted RMS with the whole budget spent greedily, whatever each pose adds:
            what "no poses would improve it by more than …" is stated with.
        worth_it: the improvement is at least that (otherwise nothing should be recorded).
        candidates: how many reachable candidates were scored.
    """

    chosen: list[Candidate]
    rms_before_mm: float
    rms_after_mm: float
    resolution: float
    minutes: float
    budget_minutes: float
    minimum_improvement: float
    best_rms_mm: float
    worth_it: bool
    candidates: int

    @property
    def observations(self) -> list[Observation]:
        return [c.observation for c in self.chosen]


def plan_excitation(
    identified: IdentificationResult,
    session: Session,
    nominal: Robot,
    budget_minutes: float = DEFAULT_BUDGET_MINUTES,
    *,
    thresholds: Thresholds = Thresholds(),
    minimum_improvement: float | None = None,
    touches: bool = TOUCHES_RECORDABLE,
) -> ExcitationPlan:
    """Choose excitation poses for a session whose robot was identified (module docstring and
    :mod:`brachycal.calibration.robot.observability`).

    Args:
        identified: the robot identified on ``session`` with ``nominal``.
        session: the recorded session.
        nominal: the robot the session was calibrated with (its URDF).
        budget_minutes: extra robot time allowed, in (0, :data:`MAX_BUDGET_MINUTES`].
        thresholds: joint margin, clearance and IK residual every pose keeps.
        minimum_improvement: relative fall of the predicted RMS landing error below which the poses
            are not worth recording; default the larger of the prediction's own uncertainty
            (:func:`~brachycal.calibration.robot.observability.resolution`) and
            :data:`MIN_IMPROVEMENT`. The greedy stops below this fraction per budget per minute.
        touches: offer touches too (default :data:`TOUCHES_RECORDABLE`).

    Raises:
        InputError: a budget out of range.
    """
    check_range(budget_minutes, "excitation budget", low=0.0, high=MAX_BUDGET_MINUTES, low_open=True, unit="min")
    fit = identified.fit
    rtips = fit.layout(nominal.joint_names).unpack(fit.x, fit.base, session.spacing_m)[3]
    robot = software_robot(identified.robot(nominal), fit, session.p_ER_Mtip)
    pool = candidates(
        robot,
        session,
        rtips,
        fit.image.spacing_m,
        thresholds=thresholds,
        samples=np.flatnonzero(~fit.outliers).tolist(),
        touches=touches,
    )
    criterion = base_criterion(identified, session, nominal)
    fraction = resolution(identified, session, nominal, criterion)
    floor = max(fraction, MIN_IMPROVEMENT) if minimum_improvement is None else minimum_improvement
    if not pool:
        rms = criterion.rms_mm
        return ExcitationPlan([], rms, rms, fraction, 0.0, budget_minutes, floor, rms, False, 0)
    rows = observation_rows(identified, session, nominal, [c.observation for c in pool])
    minutes = [c.minutes for c in pool]
    best = greedy(base_criterion(identified, session, nominal), rows, minutes, budget_minutes, 0.0).rms_mm
    selection = greedy(criterion, rows, minutes, budget_minutes, floor)
    chosen = [pool[i] for i in selection.chosen]
    # The greedy counted round trips from each source pose; the tour is usually shorter. If it is not,
    # drop the last choices until it fits (their rows are then not in the stated RMS: recompute it).
    while chosen and tour_minutes(nominal, chosen) > budget_minutes:
        chosen.pop()
    after = selection.rms_before_mm
    if chosen:
        check = base_criterion(identified, session, nominal)
        for i in selection.chosen[: len(chosen)]:
            check.add(rows[i])
        after = check.rms_mm
    worth = bool(chosen) and 1.0 - after / selection.rms_before_mm >= floor
    return ExcitationPlan(
        chosen,
        selection.rms_before_mm,
        after,
        fraction,
        tour_minutes(nominal, chosen),
        budget_minutes,
        floor,
        best,
        worth,
        len(pool),
    )


def write_excitation(plan: ExcitationPlan, robot: Robot, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write the chosen poses in visiting order (atomically), as ``plan`` writes its pose table.

    Columns: ``order,kind,label,variant,tool,reference,u_px,v_px,x,y,z`` (the tool tip's target in the
    robot's base frame, metres: the reference tip as calibrated for a touch, the needle tip for a
    sample), ``move_s`` (from the previous pose; the first from the ready stance), ``clearance_mm``,
    ``joint_margin_deg``, then the joints in the controller's order in radians and in degrees.
    A touch's ``u_px,v_px`` are empty; a sample's ``tool,reference`` are empty.
    """
    controller = robot.rig.controller_joint_names
    columns = [robot.joint_names.index(name) for name in controller]
    visit, moves, _ = tour(robot, plan.chosen)
    header = [
        "order", "kind", "label", "variant", "tool", "reference", "u_px", "v_px", "x", "y", "z",
        "move_s", "clearance_mm", "joint_margin_deg", *controller, *(f"{name}_deg" for name in controller),
    ]  # fmt: skip
    with atomic_open(path, force=force) as f:
        f.write(",".join(header) + "\n")
        for n, (k, move) in enumerate(zip(visit, moves, strict=True), start=1):
            c = plan.chosen[int(k)]
            obs = c.observation
            q = obs.q[columns]
            touch = obs.kind == TOUCH
            uv = ["", ""] if touch else [f"{obs.uv_px[0]:.3f}", f"{obs.uv_px[1]:.3f}"]
            fields = [
                str(n), obs.kind, c.label, c.variant, obs.tool, obs.reference, *uv,
                *(f"{x:.9f}" for x in c.target_m), f"{move:.3f}", f"{c.clearance_m * 1e3:.1f}",
                f"{np.degrees(c.joint_margin_rad):.2f}", *(f"{x:.9f}" for x in q), *(f"{x:.4f}" for x in np.degrees(q)),
            ]  # fmt: skip
            f.write(",".join(fields) + "\n")
    return Path(path)
