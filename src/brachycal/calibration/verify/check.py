"""Is the calibration still good? A check of a few samples against a stored result (``brachycal verify``).

Residuals are in millimetres (samples along the image's lateral, depth and normal axes; touches in
``base_link``); the test's false-alarm rate is stated (:data:`DEFAULT_FALSE_ALARM`), and a failed
check names the part that most likely moved.

Design: ``docs/design/verification.md``.
"""

from __future__ import annotations

import datetime
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brachycal._version import __version__
from brachycal.calibration.chain.image_models import image_model
from brachycal.calibration.chain.robot_terms import joint_twists, motion_rows, point_motion
from brachycal.calibration.result import Calibration
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.data.formats.csv_log import read_table, table_configurations, to_float
from brachycal.data.session import (
    CHECK_TOOLS,
    FILES,
    MIN_CHECK_SAMPLES,
    REFERENCES,
    check_robot_columns,
    read_sample_table,
    read_session_toml,
)
from brachycal.errors import DegenerateDataError, InputError
from brachycal.io import sha256_file
from brachycal.se3 import FloatArray, make_transform, transform_points
from brachycal.validate import check_range

if TYPE_CHECKING:
    from brachycal.calibration.session.result_file import ResultFile
    from brachycal.data.session import Session
    from brachycal.model.robot import Robot

#: The parts a check can name, in the order of the report; each with its parameter count
#: (the robot's is its joint count, set when the robot is known).
PARTS = ("needle tip", "probe mount", "image transform", "image scale", "robot")
#: Default false-alarm rate of the test (the goal: at most 5 % on unchanged set-ups).
DEFAULT_FALSE_ALARM = 0.05
#: Central-difference steps: 1 µm and 1 µrad (the residuals are smooth; truncation error ~step²,
#: rounding ~1e-16/step: both far below the 0.1 mm noise the residuals are compared with).
_STEP_M = 1e-6
_STEP_RAD = 1e-6


@dataclass(frozen=True)
class CheckSession:
    """A validated check session, SI units.

    Attributes:
        folder: where it was read from.
        spacing_m: ``(2,)`` nominal pixel spacing, metres per pixel; ``size_px`` ``(2,)`` image size.
        sample_ids: ``(N,)`` names; ``samples_q`` ``(N, nq)`` radians; ``uv_px`` ``(N, 2)`` annotated tips.
        touches: ``(tool, reference, trial, q (nq,))`` for the needle and probe touches (may be empty).
        inputs: file name → SHA-256.
    """

    folder: str
    spacing_m: FloatArray
    size_px: np.ndarray
    sample_ids: list[str]
    samples_q: FloatArray
    uv_px: FloatArray
    touches: list[tuple[str, str, int, FloatArray]] = field(default_factory=list)
    inputs: dict[str, str] = field(default_factory=dict)


def read_check_session(folder: str | os.PathLike[str], robot: Robot) -> CheckSession:
    """Read a check session (module docstring); refuses with one line naming the file, row and column."""

    def labels(path: Path, header: list[str], rows: list[int], records: list[list[str]], column: str, allowed):
        k = header.index(column)
        for row, fields in zip(rows, records, strict=True):
            if fields[k].strip() not in allowed:
                raise InputError(
                    f"unknown {column} {fields[k].strip()!r} (expected {', '.join(allowed)})",
                    file=path,
                    row=row,
                    column=column,
                )
        return [fields[k].strip() for fields in records]

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(
            "not a check session folder (expected a folder with session.toml and samples.csv)", file=folder
        )
    for name in ("session.toml", "samples.csv"):
        if not os.path.lexists(folder / name):  # anything else there is refused by its reader
            raise InputError("missing check session file", file=folder / name)
    spacing_m, size_px, _ = read_session_toml(folder / "session.toml")
    path = folder / "samples.csv"
    ids, q, uv = read_sample_table(path, robot, size_px)
    if len(ids) < MIN_CHECK_SAMPLES:
        raise DegenerateDataError(
            f"{len(ids)} samples: a check needs at least {MIN_CHECK_SAMPLES} (brachycal plan check plans 5 to 16)",
            file=path,
        )
    inputs = {name: sha256_file(folder / name) for name in ("session.toml", "samples.csv")}
    touches: list[tuple[str, str, int, FloatArray]] = []
    path = folder / "touches.csv"
    if os.path.lexists(path):
        header, rows, records = read_table(path, ["tool", "reference", "trial"])
        check_robot_columns(path, header, robot)
        tools = labels(path, header, rows, records, "tool", ("top_model", *CHECK_TOOLS))
        references = labels(path, header, rows, records, "reference", REFERENCES)
        trials = to_float(path, header, rows, records, ["trial"])[:, 0]
        for row, trial in zip(rows, trials, strict=True):
            if not (trial >= 1 and trial == round(trial)):
                raise InputError(
                    f"trial must be a whole number from 1, got {trial:g}", file=path, row=row, column="trial"
                )
        Q = table_configurations(path, robot, header, rows, records)
        for tool, reference, trial, config in zip(tools, references, trials, Q, strict=True):
            if tool in CHECK_TOOLS:  # the top-model locates the reference tips: the result has them
                touches.append((tool, reference, int(trial), config))
        inputs["touches.csv"] = sha256_file(path)
    return CheckSession(str(folder), spacing_m, size_px, ids, q, uv, touches, inputs)


@dataclass(frozen=True)
class NullModel:
    """The SD per coordinate of a check residual when nothing moved, metres (module docstring).

    Attributes:
        sample_sd_m: per coordinate of a sample's residual; ``sample_source`` says where from.
        touch_sd_m: tool → per coordinate of a touch's residual.
        reference_tips_m: ``rtip1``/``rtip2`` → ``(3,)`` in ``base_link``, as the result located them.
        pose_sd_m: ``(N,)`` per check sample, where the check's poses were matched to the calibration
            session's (:func:`with_calibration_poses`); ``pose_match`` the calibration sample each
            was matched to (None: no calibration sample there, the average SD is used).
        axis_scale: ``(3,)`` the sample SD's factor along the image's lateral, depth and normal axes
            (:func:`image_axis_scale`; None: the same on each).
        covariance_m2: ``(3 (N + T), 3 (N + T))`` the residuals' whole null covariance where the
            stated robot accuracy was propagated to the check (:func:`with_robot_accuracy`); its
            diagonal is at least :meth:`variances`. ``covariance_source`` says how it was made.
    """

    sample_sd_m: float
    sample_source: str
    touch_sd_m: dict[str, float]
    reference_tips_m: dict[str, FloatArray]
    touch_source: str = "mechanical.<tool>.rmse_mm / sqrt(3)"
    pose_sd_m: FloatArray | None = None
    pose_match: tuple[str | None, ...] = ()
    axis_scale: FloatArray | None = None
    covariance_m2: FloatArray | None = None
    covariance_source: str = ""

    def sample_axis_sds(self, n: int) -> FloatArray:
        """``(n, 3)`` each check sample's SD along the image's axes (lateral, depth, normal), metres:
        :meth:`sample_sds` times :attr:`axis_scale` (the image noise's share along each axis, mean
        square 1: the annotation noise lies in the plane), or the same SD on every axis."""
        sd = self.sample_sds(n)[:, None]
        return sd * (np.ones(3) if self.axis_scale is None else self.axis_scale)

    def variances(self, n: int, tools: list[str]) -> FloatArray:
        """``(3 (n + T),)`` the null variance of each check residual coordinate (samples then the
        touches of ``tools``), metres², without correlations."""
        touch = np.array([self.touch_sd_m[t] for t in tools]).reshape(-1)
        return np.concatenate([(self.sample_axis_sds(n) ** 2).ravel(), np.repeat(touch**2, 3)])

    def sample_sds(self, n: int) -> FloatArray:
        """``(n,)`` the SD per coordinate of each check sample's residual, metres: :attr:`pose_sd_m`
        where the check's poses were matched to the calibration's (:func:`with_calibration_poses`),
        else :attr:`sample_sd_m` for every sample."""
        if self.pose_sd_m is not None:
            if len(self.pose_sd_m) != n:
                raise ValueError(f"{len(self.pose_sd_m)} pose SDs for {n} check samples")
            return self.pose_sd_m
        return np.full(n, self.sample_sd_m)


def null_model(stored: ResultFile, method: str) -> NullModel:
    """The null model from the result's own leave-one-out (``loocv.<method>.rmse_mm``) and Table I
    (``mechanical.<tool>.rmse_mm``) errors, and its reference tips.

    Raises:
        InputError: the result lacks one of them (naming the key).
    """

    def rmse(block: object, key: str) -> float:
        value = block.get("rmse_mm") if isinstance(block, dict) else None
        if not isinstance(value, int | float) or isinstance(value, bool) or not np.isfinite(value) or value <= 0:
            raise InputError(
                "missing or not a positive number: the check's null needs the result's own error",
                file=stored.source,
                column=f"{key}.rmse_mm",
            )
        return float(value) * 1e-3

    raw = stored.raw
    loocv = raw.get("loocv", {}) if isinstance(raw.get("loocv"), dict) else {}
    sample_sd = rmse(loocv.get(method), f"loocv.{method}") / np.sqrt(3.0)
    mechanical = raw.get("mechanical", {}) if isinstance(raw.get("mechanical"), dict) else {}
    touch_sd = {tool: rmse(mechanical.get(tool), f"mechanical.{tool}") / np.sqrt(3.0) for tool in CHECK_TOOLS}
    touch_source = "mechanical.<tool>.rmse_mm / sqrt(3)"
    # A whole-chain result also measured the touches' scatter over all of them (some 40 degrees of
    # freedom, the robot's error at the touch configurations included, but pooled over the tools);
    # Table I's three trials per tool (9) scatter widely. Each alone let single twin seeds' checks
    # fail every time (benchmarks/verify_check.py, real-arm robot): the larger of the two is taken.
    chain = raw.get("chain", {}) if isinstance(raw.get("chain"), dict) else {}
    noise = chain.get("noise", {}).get("touch") if isinstance(chain.get("noise"), dict) else None
    if isinstance(noise, dict) and noise.get("source") == "residuals":
        value = noise.get("sd_mm")
        if isinstance(value, int | float) and not isinstance(value, bool) and np.isfinite(value) and value > 0:
            touch_sd = {tool: max(sd, float(value) * 1e-3) for tool, sd in touch_sd.items()}
            touch_source = "the larger of mechanical.<tool>.rmse_mm / sqrt(3) and chain.noise.touch.sd_mm"
    tips = raw.get("reference_tips_m", {})
    reference: dict[str, FloatArray] = {}
    for name in ("rtip1", "rtip2"):
        value = tips.get(name) if isinstance(tips, dict) else None
        try:
            p = np.array(value, dtype=float)
        except (TypeError, ValueError):
            p = np.zeros(0)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError("must be 3 finite numbers (metres)", file=stored.source, column=f"reference_tips_m.{name}")
        reference[name] = p
    return NullModel(
        sample_sd,
        f"loocv.{method}.rmse_mm / sqrt(3)",
        touch_sd,
        reference,
        touch_source,
        axis_scale=image_axis_scale(stored) if method == "chain" else None,
    )


def _chain_section(stored: ResultFile) -> dict:
    chain = stored.raw.get("chain")
    return chain if isinstance(chain, dict) else {}


def _positive(value: object) -> float | None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and np.isfinite(value) and value > 0
    return float(value) if ok else None  # type: ignore[arg-type]


def image_axis_noise_m(stored: ResultFile) -> FloatArray | None:
    """``(3,)`` the whole chain's image noise along the image's lateral, depth and normal axes,
    metres (``chain.image_noise_along_axes``), or None if the result does not state all three."""
    levels = _chain_section(stored).get("image_noise_along_axes")
    if not isinstance(levels, dict):
        return None
    values = [_positive(levels.get(a, {}).get("sd_mm")) if isinstance(levels.get(a), dict) else None for a in AXES]
    if any(v is None for v in values):
        return None
    return np.array(values, dtype=float) * 1e-3


def image_axis_scale(stored: ResultFile) -> FloatArray | None:
    """``(3,)`` factors of a sample's null SD along the image's axes: the chain's image noise along
    each (:func:`image_axis_noise_m`) over their root mean square (the per-coordinate SD keeps the
    same total, spread as the noise is: the annotation noise lies in the plane, so a part that moves
    the samples in the plane, e.g. the scale, is not tested against a level that pools the normal)."""
    levels = image_axis_noise_m(stored)
    if levels is None:
        return None
    return levels / np.sqrt(np.mean(levels**2))


#: A sample residual's axes, in :meth:`ChainModel.residuals`' order.
AXES = ("lateral", "depth", "normal")


#: A check sample is at a calibration sample's pose when the needle tip lies within this of
#: where it lay then (in ``base_link``; the plan's grid points are some 13 mm apart, and the needle
#: arm returns to its planned joints to the encoders' ~0.02 mm) ...
SAME_NEEDLE_TIP_M = 2e-3
#: ... and the probe flange within this (the probe arm is adjusted until the tip shows at its
#: planned pixel: a fraction of a millimetre from the calibration's adjustment).
SAME_PROBE_FLANGE_M = 5e-3


def with_calibration_poses(
    null: NullModel,
    stored: ResultFile,
    method: str,
    robot: Robot,
    calibration: Session,
    check: CheckSession,
    *,
    calibration_folder: str | os.PathLike[str] = "calibration session",
) -> NullModel:
    """``null`` with each check sample's own SD: where a check pose repeats a calibration sample's
    pose (:data:`SAME_NEEDLE_TIP_M`, :data:`SAME_PROBE_FLANGE_M`), the larger of the average
    (``loocv.<method>.rmse_mm / √3``) and that sample's own leave-one-out error / √3.

    Why: the robot's geometric error left over after calibration is repeatable and grows towards
    the cube's corners, where the check's D-optimal pick goes; the average under-states it there
    (on real-arm twins the corner pose's residual variance ran 2.4 times the average and false
    alarms reached 11–16 % instead of 5 %). The calibration already measured what a new
    observation at that pose misses by: its leave-one-out error there. One 3D error is a 3-dof
    estimate, so it may raise a pose's SD above the average, never lower it; samples the chain
    flagged as outliers keep the average.

    Raises:
        InputError: ``calibration`` is not the session the result was calibrated from (other
            sample names, or its files' SHA-256 differ from the result's ``inputs``).
    """
    folder = Path(calibration_folder)
    ids = stored.raw.get("samples")
    loocv = stored.raw.get("loocv", {}).get(method) if isinstance(stored.raw.get("loocv"), dict) else None
    errors = loocv.get("errors_mm") if isinstance(loocv, dict) else None
    if not isinstance(ids, list) or not isinstance(errors, list) or len(errors) != len(ids):
        raise InputError(
            "the result has no per-sample leave-one-out errors to match the check's poses with",
            file=stored.source,
            column=f"loocv.{method}.errors_mm",
        )
    if list(calibration.sample_ids) != [str(i) for i in ids]:
        raise InputError(
            f"not the session this result was calibrated from: its {len(calibration.sample_ids)} samples are not "
            f"the result's {len(ids)} (samples)",
            file=folder / "samples.csv",
        )
    recorded = stored.raw.get("inputs", {}) if isinstance(stored.raw.get("inputs"), dict) else {}
    for name in FILES:
        if name in recorded and name in calibration.inputs and recorded[name] != calibration.inputs[name]:
            raise InputError(
                "not the session this result was calibrated from: its SHA-256 differs from the result's inputs",
                file=folder / name,
            )
    e_m = np.array(errors, dtype=float) * 1e-3
    chain = stored.raw.get("chain", {}) if isinstance(stored.raw.get("chain"), dict) else {}
    outliers = set(chain.get("outliers", [])) if isinstance(chain.get("outliers", []), list) else set()
    rig = robot.rig
    T_ER_Ntip = stored.T_ER_Ntip

    def places(Q: FloatArray) -> tuple[FloatArray, FloatArray]:
        T_R_EL, T_R_ER = robot.fk_frames([rig.probe_flange, rig.needle_flange], Q)
        return (T_R_ER @ T_ER_Ntip)[:, :3, 3], T_R_EL[:, :3, 3]

    tip_cal, probe_cal = places(np.asarray(calibration.samples_q, dtype=float))
    tip_check, probe_check = places(np.asarray(check.samples_q, dtype=float))
    sd = np.full(len(check.samples_q), null.sample_sd_m)
    match: list[str | None] = []
    for i in range(len(sd)):
        d_tip = np.linalg.norm(tip_cal - tip_check[i], axis=1)
        d_probe = np.linalg.norm(probe_cal - probe_check[i], axis=1)
        same = (d_tip <= SAME_NEEDLE_TIP_M) & (d_probe <= SAME_PROBE_FLANGE_M)
        if not same.any():
            match.append(None)
            continue
        j = int(np.argmin(np.where(same, d_tip, np.inf)))
        match.append(str(ids[j]))
        if str(ids[j]) not in outliers:
            sd[i] = max(null.sample_sd_m, e_m[j] / np.sqrt(3.0))
    source = (
        f"per check pose: the larger of loocv.{method}.rmse_mm / sqrt(3) and the matched calibration sample's "
        f"loocv.{method}.errors_mm / sqrt(3) ({sum(m is not None for m in match)} of {len(match)} poses matched)"
    )
    return replace(null, pose_sd_m=sd, pose_match=tuple(match), sample_source=source)


def stated_robot_accuracy(stored: ResultFile) -> RobotAccuracy | None:
    """The robot accuracy the calibration was stated with (``chain.robot_accuracy``), or None."""
    stated = _chain_section(stored).get("robot_accuracy")
    if not isinstance(stated, dict):
        return None
    mm, deg = _positive(stated.get("joint_translation_sd_mm")), _positive(stated.get("joint_rotation_sd_deg"))
    if mm is None and deg is None:
        return None
    try:
        return RobotAccuracy(
            (mm or 0.0) * 1e-3, float(np.radians(deg or 0.0)), source=str(stated.get("source", "the result"))
        )
    except InputError as error:
        raise InputError(str(error), file=stored.source, column="chain.robot_accuracy") from None


#: Smallest noise SD a residual is weighted with when propagating the robot accuracy (m): a group
#: whose residuals are below resolution would otherwise weigh without bound.
_MIN_NOISE_SD_M = 1e-5


def robot_rows(model: ChainModel, session: CheckSession) -> FloatArray:
    """``(3 (N + T), 6 nq)`` how the check residuals (metres: samples along the stored image's axes,
    touches in ``base_link``) move with every joint origin's small motion ``(v, ω)`` (the stated
    accuracy's parameters, :func:`~brachycal.calibration.chain.joint_twists`' order)."""

    robot, rig = model.robot, model.robot.rig
    T_R_EL, T_R_ER = model._flanges(session, np.zeros(robot.nq))
    p_I = np.column_stack([session.uv_px * model.spacing_m, np.zeros(len(session.uv_px)), np.ones(len(session.uv_px))])
    p_image = np.einsum("nij,nj->ni", T_R_EL @ model.T_EL_Ptip @ model.T_Ptip_I, p_I)[:, :3]
    p_needle = (T_R_ER[:, :3, :3] @ model.T_ER_Ntip[:3, 3]) + T_R_ER[:, :3, 3]
    W_EL = joint_twists(robot, session.samples_q, rig.probe_flange)
    W_ER = joint_twists(robot, session.samples_q, rig.needle_flange)
    base = motion_rows(point_motion(p_image), W_EL) - motion_rows(point_motion(p_needle), W_ER)
    R_R_I = model._image_axes(session)
    samples = np.einsum("nji,njk->nik", R_R_I, base.reshape(len(p_I), 3, -1)).reshape(3 * len(p_I), -1)
    parts = [samples]
    for tool, _, _, q in session.touches:
        needle = tool == "needle"
        flange = rig.needle_flange if needle else rig.probe_flange
        p_tool = (model.T_ER_Ntip if needle else model.T_EL_Ptip)[:3, 3]
        T = robot.fk(flange, q)
        parts.append(motion_rows(point_motion((T[:3, :3] @ p_tool + T[:3, 3])[None]), joint_twists(robot, q, flange)))
    return np.vstack(parts)


def _part_columns(model: ChainModel, session: CheckSession, scaled: tuple[int, ...]) -> FloatArray:
    """``(3 (N + T), 15 + len(scaled) + 6)`` the check residuals' Jacobian (metres) with respect to
    what the calibration estimated: needle tip, probe mount, image transform, the spacing of the
    image axes ``scaled`` (0: u, 1: v) and the reference tips."""
    unit = replace(
        model.null,
        sample_sd_m=1.0,
        pose_sd_m=None,
        axis_scale=None,
        covariance_m2=None,
        touch_sd_m=dict.fromkeys(CHECK_TOOLS, 1.0),
    )
    J = replace(model, null=unit, _axes_cache={}).jacobian(session)[:, [*range(15), *(15 + a for a in scaled)]]
    tips = np.zeros((len(J), 6))
    for k, (_, reference, _, _) in enumerate(session.touches):
        row = 3 * (len(session.uv_px) + k)
        col = 0 if reference == "rtip1" else 3
        tips[row : row + 3, col : col + 3] = -np.eye(3)
    return np.hstack([J, tips])


def with_robot_accuracy(
    null: NullModel,
    stored: ResultFile,
    method: str,
    robot: Robot,
    calibration: Session,
    check: CheckSession,
    accuracy: RobotAccuracy,
) -> NullModel:
    """``null`` with the whole covariance of the check's residuals under the robot accuracy the
    calibration was stated with, propagated to the check's own poses and touches.

    The physical joints' origins are off by ``c ~ N(0, Σ_c)`` (the stated accuracy). The calibration
    (linearised: its image samples and needle and probe touches, weighted as it was, by each
    group's level ``chain.noise``) absorbed ``S c`` into its estimate, ``S`` the weighted least
    squares of the calibration's robot Jacobian ``G`` on its parameters' ``J`` (needle tip, probe
    mount, image transform, scale, reference tips). A check residual then holds its own noise, the
    calibration's noise ``J_k (Jᵀ W J)⁻¹ J_kᵀ`` and what the calibration could not absorb at the
    check's configurations, ``(G_k − J_k S) Σ_c (G_k − J_k S)ᵀ`` (the check's own noise at the
    groups' whole levels, which hold the robot's scatter at the calibration's configurations too:
    counted twice rather than leaving out the touches' jog where a stated accuracy explains all
    their scatter, which took the model's correlations as exact): correlated across the check's
    samples and touches (the same robot), and new at configurations the calibration never saw
    (touches turned by hand). Its diagonal is raised to at least ``null``'s variances (each pose's
    own leave-one-out error, the touches' measured scatter): the model adds the correlations and
    the new configurations' error, and never lowers what the calibration measured.
    """
    model = replace(chain_model(stored, method, robot), null=null, _axes_cache={})
    chain = _chain_section(stored)
    outliers = set(chain.get("outliers", [])) if isinstance(chain.get("outliers", []), list) else set()
    keep = np.array([str(i) not in outliers for i in calibration.sample_ids], dtype=bool)
    touches = [
        (tool, reference, int(trial), np.asarray(q, dtype=float))
        for (tool, reference), recorded in calibration.touches.items()
        if tool in CHECK_TOOLS
        for trial, q in zip(recorded.trials, recorded.q, strict=True)
    ]
    session = CheckSession(
        "calibration",
        calibration.spacing_m,
        calibration.size_px,
        [],
        calibration.samples_q[keep],
        calibration.uv_px[keep],
        touches,
    )
    noise = chain.get("noise", {}) if isinstance(chain.get("noise"), dict) else {}

    def level(group: str) -> float:
        # The group's whole level, the robot's share kept: the calibration was weighted with it, and
        # where a stated accuracy over-explains the scatter (share 0) the jog and the readings'
        # noise would otherwise be left out, and the model's correlations taken as exact.
        entry = noise.get(group)
        sd = _positive(entry.get("sd_mm")) if isinstance(entry, dict) else None
        return max((sd or 0.0) * 1e-3, _MIN_NOISE_SD_M)

    axes = image_axis_noise_m(stored)
    image_sd = np.full(3, level("image")) if axes is None else axes * level("image") / np.sqrt(np.mean(axes**2))
    image_sd = np.maximum(image_sd, _MIN_NOISE_SD_M)

    def noise_sds(s: CheckSession) -> FloatArray:
        return np.concatenate([np.tile(image_sd, len(s.uv_px)), np.full(3 * len(s.touches), level("touch"))])

    try:  # the image axes whose spacing the calibration estimated
        scaled = tuple(sorted({a for axes in image_model(str(chain.get("model"))).scaled_axes for a in axes}))
    except InputError:
        scaled = (0, 1)
    J_cal, J_check = _part_columns(model, session, scaled), _part_columns(model, check, scaled)
    G_cal, G_check = robot_rows(model, session), robot_rows(model, check)
    w = 1.0 / noise_sds(session)
    A = J_cal * w[:, None]
    A_pinv = np.linalg.pinv(A, rcond=1e-10)
    S = A_pinv @ (G_cal * w[:, None])
    D = G_check - J_check @ S
    C = np.diag(noise_sds(check) ** 2) + J_check @ (A_pinv @ A_pinv.T) @ J_check.T
    C += D @ accuracy.covariance(robot) @ D.T
    floor = null.variances(len(check.uv_px), [t[0] for t in check.touches])
    C[np.diag_indices_from(C)] = np.maximum(np.diag(C), floor)
    source = (
        f"the stated robot accuracy ({accuracy.translation_sd_m * 1e3:g} mm / "
        f"{np.degrees(accuracy.rotation_sd_rad):g} deg per joint) propagated to the check's poses and touches, "
        "with the calibration's noise; each variance at least the per-pose null's"
    )
    return replace(null, covariance_m2=C, covariance_source=source)


def chi2_sf(x: float, dof: int) -> float:
    """``P(χ²_dof > x)`` (SciPy's special functions: ``scipy.stats`` takes seconds to import)."""
    from scipy.special import gammaincc  # lazy: start-up (scipy)

    return float(gammaincc(dof / 2.0, x / 2.0))


def chi2_isf(alpha: float, dof: int) -> float:
    """The ``1 − alpha`` quantile of χ²_dof."""
    from scipy.special import gammainccinv  # lazy: start-up (scipy)

    return float(2.0 * gammainccinv(dof / 2.0, alpha))


def _rotation(omega: FloatArray) -> FloatArray:
    """Rodrigues: the rotation matrix of a rotation vector (radians)."""
    angle = float(np.linalg.norm(omega))
    K = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    if angle < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(angle) / angle * K + (1 - np.cos(angle)) / angle**2 * K @ K


def small_motion(v: FloatArray, omega: FloatArray) -> FloatArray:
    """A small rigid motion: rotation vector ``omega`` (rad) then translation ``v`` (m)."""
    return make_transform(_rotation(omega), v)


@dataclass(frozen=True)
class ChainModel:
    """The predicted check residuals as a function of small changes of each part.

    ``x`` stacks ``[needle (3, m), probe mount (6: v m, ω rad at Ptip), image (6: at I),
    scale (2: relative change of s_u, s_v), robot (nq joint zero offsets, rad)]``.
    """

    robot: Robot
    calibration: Calibration
    null: NullModel
    _axes_cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def T_ER_Ntip(self) -> FloatArray:
        """``(4, 4)`` the calibrated needle tip in the needle flange, metres."""
        return self.calibration.T_ER_Ntip

    @property
    def T_EL_Ptip(self) -> FloatArray:
        """``(4, 4)`` the calibrated probe tip in the probe flange, metres."""
        return self.calibration.T_EL_Ptip

    @property
    def T_Ptip_I(self) -> FloatArray:
        """``(4, 4)`` the calibrated image frame in the probe tip, metres."""
        return self.calibration.T_Ptip_I

    @property
    def spacing_m(self) -> FloatArray:
        """``(2,)`` the calibrated pixel spacing ``(s_u, s_v)``, metres."""
        return np.asarray(self.calibration.spacing_m, dtype=float)

    @property
    def blocks(self) -> dict[str, slice]:
        nq = self.robot.nq
        return {
            "needle tip": slice(0, 3),
            "probe mount": slice(3, 9),
            "image transform": slice(9, 15),
            "image scale": slice(15, 17),
            "robot": slice(17, 17 + nq),
        }

    @property
    def size(self) -> int:
        return 17 + self.robot.nq

    def residuals(self, x: FloatArray, session: CheckSession) -> tuple[FloatArray, FloatArray]:
        """``(sample residuals (N, 3), touch residuals (T, 3))``, metres: samples along the stored
        calibration's image axes (lateral, depth, normal) at each pose, touches in ``base_link``."""
        robot, rig = self.robot, self.robot.rig
        p_ER_Ntip = self.T_ER_Ntip[:3, 3] + x[0:3]
        T_EL_Ptip = self.T_EL_Ptip @ small_motion(x[3:6], x[6:9])
        T_Ptip_I = self.T_Ptip_I @ small_motion(x[9:12], x[12:15])
        spacing = self.spacing_m * (1.0 + x[15:17])
        offsets = x[17:]
        T_R_EL, T_R_ER = self._flanges(session, offsets)
        p_I = np.column_stack([session.uv_px * spacing, np.zeros(len(session.uv_px))])
        p_image = np.einsum("nij,nj->ni", T_R_EL @ T_EL_Ptip @ T_Ptip_I, np.column_stack([p_I, np.ones(len(p_I))]))
        p_needle = transform_points(T_R_ER, p_ER_Ntip)
        # Along the stored calibration's image axes at each pose (x-independent: a fixed frame).
        R_R_I = self._image_axes(session)
        samples = np.einsum("nji,nj->ni", R_R_I, p_image[:, :3] - p_needle)
        touches = np.zeros((len(session.touches), 3))
        if session.touches:
            Q = np.array([t[3] for t in session.touches]) + offsets
            T_R_EL_touch, T_R_ER_touch = robot.fk_frames([rig.probe_flange, rig.needle_flange], Q)
        for k, (tool, reference, _, _) in enumerate(session.touches):
            if tool == "needle":
                p = transform_points(T_R_ER_touch[k], p_ER_Ntip)
            else:
                p = transform_points(T_R_EL_touch[k], T_EL_Ptip[:3, 3])
            touches[k] = p - self.null.reference_tips_m[reference]
        return samples, touches

    def _flanges(self, session: CheckSession, offsets: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(T_R_EL, T_R_ER)`` ``(N, 4, 4)`` at the samples' joints plus ``offsets``; those at zero
        offsets are kept (the Jacobian's tool columns evaluate them 34 times)."""
        rig = self.robot.rig
        if np.any(offsets):
            poses = self.robot.fk_frames([rig.probe_flange, rig.needle_flange], session.samples_q + offsets)
            return poses[0], poses[1]
        key = ("flanges", id(session.samples_q))
        if key not in self._axes_cache:
            self._axes_cache[key] = self.robot.fk_frames([rig.probe_flange, rig.needle_flange], session.samples_q)
        poses = self._axes_cache[key]
        return poses[0], poses[1]

    def _image_axes(self, session: CheckSession) -> FloatArray:
        """``(N, 3, 3)`` the stored calibration's image axes in ``base_link`` at the samples' joints."""
        key = id(session.samples_q)
        if self._axes_cache.get("key") != key:
            T_R_EL = self.robot.fk(self.robot.rig.probe_flange, session.samples_q)
            self._axes_cache.update(key=key, axes=(T_R_EL @ self.T_EL_Ptip @ self.T_Ptip_I)[:, :3, :3])
        return self._axes_cache["axes"]

    def normalised(self, x: FloatArray, session: CheckSession) -> FloatArray:
        """All residuals divided by their null SD, flattened ``(3 (N + T),)``; with a whole null
        covariance ``Σ = L Lᵀ`` (:attr:`NullModel.covariance_m2`), whitened: ``L⁻¹ r``."""
        samples, touches = self.residuals(x, session)
        raw = np.concatenate([samples.ravel(), touches.ravel()])
        L = self.null_factor(session)
        if L is not None:
            from scipy.linalg import solve_triangular  # lazy: start-up (scipy.linalg, only a whole null needs it)

            return solve_triangular(L, raw, lower=True)
        return raw / np.sqrt(self.null.variances(len(samples), [t[0] for t in session.touches]))

    def null_factor(self, session: CheckSession) -> FloatArray | None:
        """The Cholesky factor ``L`` of the whole null covariance (None: the residuals are independent)."""
        C = self.null.covariance_m2
        if C is None:
            return None
        if len(C) != 3 * (len(session.uv_px) + len(session.touches)):
            raise ValueError(f"a null covariance of {len(C)} rows for {len(session.uv_px)} samples")
        key = ("cholesky", id(C))
        if key not in self._axes_cache:
            self._axes_cache[key] = np.linalg.cholesky(C)
        return self._axes_cache[key]

    def jacobian(self, session: CheckSession) -> FloatArray:
        """``(3 (N + T), size)`` of :meth:`normalised` at ``x = 0`` by central differences."""
        x0 = np.zeros(self.size)
        steps = np.full(self.size, _STEP_RAD)
        steps[[0, 1, 2, 3, 4, 5, 9, 10, 11]] = _STEP_M
        columns = []
        for j, h in enumerate(steps):
            dx = x0.copy()
            dx[j] = h
            columns.append((self.normalised(dx, session) - self.normalised(-dx, session)) / (2 * h))
        return np.column_stack(columns)


def chain_model(stored: ResultFile, method: str, robot: Robot) -> ChainModel:
    """The model of the stored calibration (``method``'s image transform) on ``robot`` (the software
    robot: :meth:`ResultFile.software_robot`)."""
    return ChainModel(robot, stored.calibration(method), null_model(stored, method))


@dataclass(frozen=True)
class PartFit:
    """One hypothesis "only this part moved", fitted to the check's normalised residuals.

    Attributes:
        part: :data:`PARTS` name; ``parameters`` its count, ``rank`` how many the check determines.
        delta: ``(k,)`` the change (the part's parameters, SI) that explains the residuals; ``sd``
            its SD from ``(J_hᵀJ_h)⁻¹`` (inf where undetermined).
        explained: ``|J_h δ|²`` (the GLR statistic); ``remaining``: ``|r − J_h δ|²``, its degrees of
            freedom ``dof`` and p-value ``p_remaining`` (is what is left noise?).
        targeting_mm: RMS over the check's sample poses of the fitted sample residuals (the targeting
            error if this change were ignored), mm.
        log_evidence: the hypothesis's Bayesian log evidence (how the part is named).
        prior_multiples: the largest ``|δ̂_i| / prior SD_i``: how far the change lies beyond the small
            changes the linear model describes (:data:`GROSS_PRIOR_MULTIPLES`).
        threshold: the χ² quantile (``rank`` degrees of freedom) that :attr:`explained` is tested
            against (:func:`union_test`).
    """

    part: str
    parameters: int
    rank: int
    delta: FloatArray
    sd: FloatArray
    explained: float
    remaining: float
    dof: int
    p_remaining: float
    targeting_mm: float
    log_evidence: float = 0.0
    prior_multiples: float = 0.0
    threshold: float = float("inf")

    @property
    def fired(self) -> bool:
        """Whether this part's own test (:attr:`explained` against :attr:`threshold`) fails."""
        return self.explained > self.threshold

    def size_text(self) -> str:
        """How much it moved, as a person reads it."""
        d, s = self.delta, self.sd
        if self.part == "needle tip":
            return f"{np.linalg.norm(d) * 1e3:.2f} mm ({_vector_mm(d, s)})"
        if self.part in ("probe mount", "image transform"):
            return (
                f"{np.linalg.norm(d[:3]) * 1e3:.2f} mm and {np.degrees(np.linalg.norm(d[3:])):.2f} deg "
                f"(shift {_vector_mm(d[:3], s[:3])}; turn {_vector_deg(d[3:], s[3:])})"
            )
        if self.part == "image scale":
            return f"lateral {100 * d[0]:+.2f} ± {100 * s[0]:.2f} %, depth {100 * d[1]:+.2f} ± {100 * s[1]:.2f} %"
        k = int(np.argmax(np.abs(d)))
        return f"largest joint zero change {np.degrees(d[k]):+.4f} ± {np.degrees(s[k]):.4f} deg (joint {k + 1})"

    def as_json(self, joint_names: tuple[str, ...] = ()) -> dict[str, object]:
        def finite(values: FloatArray) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in values]

        out: dict[str, object] = {
            "part": self.part,
            "parameters": self.parameters,
            "determined": self.rank,
            "explained_chi2": self.explained,
            "explained_threshold": float(self.threshold) if np.isfinite(self.threshold) else None,
            "remaining_chi2": self.remaining,
            "remaining_dof": self.dof,
            "remaining_p": self.p_remaining,
            "targeting_if_ignored_mm": self.targeting_mm,
            "size": self.size_text(),
        }
        d, s = self.delta, self.sd
        if self.part == "needle tip":
            out["shift_mm"], out["shift_sd_mm"] = finite(d * 1e3), finite(s * 1e3)
        elif self.part in ("probe mount", "image transform"):
            out["shift_mm"], out["shift_sd_mm"] = finite(d[:3] * 1e3), finite(s[:3] * 1e3)
            out["turn_deg"], out["turn_sd_deg"] = finite(np.degrees(d[3:])), finite(np.degrees(s[3:]))
        elif self.part == "image scale":
            out["scale_change_percent"], out["scale_change_sd_percent"] = finite(100 * d), finite(100 * s)
        else:
            names = joint_names or tuple(f"joint{k + 1}" for k in range(len(d)))
            out["joint_zero_change_deg"] = dict(zip(names, finite(np.degrees(d)), strict=True))
            out["joint_zero_change_sd_deg"] = dict(zip(names, finite(np.degrees(s)), strict=True))
        return out


def _vector_mm(d: FloatArray, s: FloatArray) -> str:
    return ", ".join(f"{a * 1e3:+.2f}±{b * 1e3:.2f}" for a, b in zip(d, s, strict=True)) + " mm"


def _vector_deg(d: FloatArray, s: FloatArray) -> str:
    return ", ".join(f"{np.degrees(a):+.2f}±{np.degrees(b):.2f}" for a, b in zip(d, s, strict=True)) + " deg"


#: A fitted change beyond this many prior SDs (:func:`prior_sd`) is not reported as a size: the
#: check's linear model holds for small changes (a remount of a few mm and degrees is ~3 prior SDs),
#: and a part that must move 10 SDs to explain the residuals points to a gross error — a touch at
#: the wrong reference tip, a mislabelled sample — more than to that part.
GROSS_PRIOR_MULTIPLES = 10.0
#: Prior SDs of a change of each part, for naming the part (Bayesian evidence: a hypothesis with
#: many parameters is not preferred merely because it fits noise). Per axis: a mount moves by
#: about a millimetre and a degree (a remount, a re-seated probe, a bent or other needle); a
#: speed of sound by a few % (1450–1600 m/s in tissue against the scanner's 1540); a joint zero by
#: what a robot's service or a collision shifts, 0.05°.
PRIOR_MOUNT_M = 1e-3
PRIOR_MOUNT_RAD = float(np.radians(1.0))
PRIOR_SCALE = 0.03
PRIOR_JOINT_RAD = float(np.radians(0.05))

#: Two hypotheses whose remaining χ² agree to this (relative) explain the check equally: the same
#: column space (the probe mount and the image transform seen by samples alone agree to ~1e-9,
#: the finite differences' rounding); distinct hypotheses differ by whole units of χ².
TIE_RELATIVE = 1e-6

#: Singular values of a normalised part Jacobian below this fraction of its largest are directions
#: the check does not determine (left out of the fit; their SD reported as infinite). The parts'
#: columns are normalised residuals per SI unit, so the ratio is their conditioning alone.
RANK_RCOND = 1e-6


def prior_sd(part: str, nq: int) -> FloatArray:
    """The prior SD of each parameter of ``part`` (SI), for the evidence that names the part."""
    return {
        "needle tip": np.full(3, PRIOR_MOUNT_M),
        "probe mount": np.array([PRIOR_MOUNT_M] * 3 + [PRIOR_MOUNT_RAD] * 3),
        "image transform": np.array([PRIOR_MOUNT_M] * 3 + [PRIOR_MOUNT_RAD] * 3),
        "image scale": np.full(2, PRIOR_SCALE),
        "robot": np.full(nq, PRIOR_JOINT_RAD),
    }[part]


def fit_part(
    part: str, J: FloatArray, r: FloatArray, n_samples: int, prior: FloatArray | None = None
) -> tuple[PartFit, FloatArray]:
    """Fit ``r ≈ −J δ`` (``J`` the part's columns) by least squares (module docstring); also returns
    the fitted sample residuals ``(n_samples, 3)`` (normalised). With ``prior`` (``(k,)`` SDs of the
    parameters), the fit's ``log_evidence`` is that of ``r ~ N(0, I + J diag(prior²) Jᵀ)``."""
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    keep = s > (s[0] * RANK_RCOND if s.size and s[0] > 0 else np.inf)
    rank = int(keep.sum())
    coeff = U[:, keep].T @ r
    delta = -(Vt[keep].T @ (coeff / s[keep]))
    fitted = -(J @ delta)  # the residuals this change explains
    explained = float(coeff @ coeff)
    remaining = float(r @ r) - explained
    dof = len(r) - rank
    p_remaining = chi2_sf(max(remaining, 0.0), dof) if dof > 0 else 1.0
    var = np.full(J.shape[1], np.inf)
    if rank:
        determined = Vt[keep]
        cov_diag = np.sum((determined.T / s[keep]) ** 2, axis=1)
        # Directions the check does not see leave their parameters undetermined.
        null = Vt[~keep]
        touched = np.sum(null**2, axis=0) > 1e-12 if null.size else np.zeros(J.shape[1], dtype=bool)
        var = np.where(touched, np.inf, cov_diag)
    fitted_samples = fitted[: 3 * n_samples].reshape(n_samples, 3)
    log_evidence = -0.5 * float(r @ r)
    if prior is not None:
        A = J * prior  # (I + A Aᵀ)⁻¹ and its log det through the k x k form (Woodbury)
        small = np.eye(A.shape[1]) + A.T @ A
        y = A.T @ r
        log_evidence = -0.5 * (float(r @ r) - float(y @ np.linalg.solve(small, y))) - 0.5 * np.linalg.slogdet(small)[1]
    return PartFit(
        part, J.shape[1], rank, delta, np.sqrt(var), explained, remaining, dof, p_remaining, 0.0, log_evidence
    ), fitted_samples


@dataclass(frozen=True, repr=False)
class CheckOutcome:
    """What ``brachycal verify`` decides.

    Attributes:
        statistic: ``Σ r²`` of the normalised residuals; ``dof`` its degrees of freedom;
            ``threshold`` the χ² quantile at ``1 − false_alarm / 2``; ``p_value`` the whole test's
            (:func:`union_test`: this χ² and each part's explained χ², Bonferroni-adjusted).
        verdict: ``"PASS"`` or ``"RECALIBRATE"``.
        part: the part that most likely moved (None on PASS), ``fits`` every hypothesis.
        sample_residuals_mm: ``(N, 3)`` (lateral, depth, normal); ``touch_residuals_mm`` ``(T, 3)``.
    """

    method: str
    false_alarm: float
    statistic: float
    dof: int
    threshold: float
    p_value: float
    verdict: str
    part: PartFit | None
    fits: list[PartFit]
    null: NullModel
    sample_residuals_mm: FloatArray
    touch_residuals_mm: FloatArray
    sample_ids: list[str]
    touches: list[tuple[str, str, int]]
    residual_rms_mm: float

    def __repr__(self) -> str:
        part = "" if self.part is None else f"; the part that moved: {self.part.part}"
        return (
            f"CheckOutcome {self.verdict} ({self.method!r}): chi-square {self.statistic:.1f} on {self.dof} dof, "
            f"threshold {self.threshold:.1f}, p = {self.p_value:.3g}{part}; "
            f"{len(self.sample_ids)} samples, {len(self.touches)} touches, residual RMS {self.residual_rms_mm:.3f} mm"
        )

    @property
    def passed(self) -> bool:
        return self.verdict == "PASS"

    @property
    def alternatives(self) -> list[str]:
        """Other parts that explain the residuals exactly as well as :attr:`part` (the check cannot
        tell them apart: e.g. probe mount and image transform without a probe touch)."""
        if self.part is None:
            return []
        best = self.part.remaining
        return [
            f.part
            for f in self.fits
            if f.part != self.part.part and abs(f.remaining - best) <= TIE_RELATIVE * max(abs(best), 1.0)
        ]


def union_test(
    statistic: float, dof: int, fits: list[PartFit], false_alarm: float
) -> tuple[bool, float, float, list[PartFit]]:
    """The check's test: RECALIBRATE when the χ² of all residuals exceeds its quantile at
    ``1 − α/2``, or when any part's explained χ² (the part fitted alone: ``|J_h δ̂|²``, χ² with
    ``rank`` degrees of freedom when nothing moved) exceeds its quantile at ``1 − α/(2P)``, ``P`` the
    parts the check determines. By the union bound, at most ``α`` false alarms in all.

    Why both: a change of one part moves the residuals along that part's few directions; its
    explained χ² gathers the signal that the all-residual χ² spreads over ``3 (N + T)`` degrees of
    freedom (95 % power needs a non-centrality of ~30 on 6 degrees of freedom at 0.5 %, ~34 on 27
    at 5 %), while the all-residual χ² still sees what no single part explains.

    Returns:
        ``(failed, threshold, p_value, fits)``: whether it fails, the all-residual threshold, the
        test's p-value (the smallest Bonferroni-adjusted one: ``min(1, 2 p_all, 2P p_h)``) and the
        fits with their thresholds set.
    """
    tested = [f for f in fits if f.rank > 0]
    alpha_part = false_alarm / (2 * max(len(tested), 1))
    threshold = chi2_isf(false_alarm / 2, dof)
    p_values = [2 * chi2_sf(statistic, dof)]
    out = []
    for fit in fits:
        if fit.rank > 0:
            fit = replace(fit, threshold=chi2_isf(alpha_part, fit.rank))
            p_values.append(2 * len(tested) * chi2_sf(fit.explained, fit.rank))
        out.append(fit)
    failed = statistic > threshold or any(f.fired for f in out)
    return failed, threshold, min(1.0, min(p_values)), out


def check_calibration(
    stored: ResultFile,
    method: str,
    robot: Robot,
    session: CheckSession,
    *,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    calibration: Session | None = None,
    calibration_folder: str | os.PathLike[str] = "calibration session",
) -> CheckOutcome:
    """Test the stored calibration on a check session (module docstring).

    ``robot``: the software robot (the result's corrections applied). ``calibration``: the session
    the result was calibrated from, for each check pose's own null SD
    (:func:`with_calibration_poses`); without it every sample has the average one. Raises
    :class:`InputError` for a false-alarm rate outside (0, 0.5], a check session whose image
    spacing differs from the calibrated session's or a calibration session that is not the
    result's, and :class:`DegenerateDataError` for a check without samples.
    """
    check_range(false_alarm, "false-alarm rate", low=0.0, high=0.5, low_open=True)
    if len(session.uv_px) == 0:
        raise DegenerateDataError("the check session has no samples", file=Path(session.folder) / "samples.csv")
    model = chain_model(stored, method, robot)
    if calibration is not None:
        null = with_calibration_poses(
            model.null, stored, method, robot, calibration, session, calibration_folder=calibration_folder
        )
        accuracy = stated_robot_accuracy(stored)
        if accuracy is not None and method == "chain":
            null = with_robot_accuracy(null, stored, method, robot, calibration, session, accuracy)
        model = replace(model, null=null, _axes_cache={})
    calibrated = calibrated_nominal_spacing(stored)
    if calibrated is not None and not np.allclose(session.spacing_m, calibrated, rtol=1e-6, atol=0.0):
        raise InputError(
            f"image spacing {_mm(session.spacing_m)} mm differs from the calibrated session's {_mm(calibrated)} mm: "
            "another scanner setting (depth/zoom) needs its own calibration",
            file=Path(session.folder) / "session.toml",
            key="image.spacing_mm",
        )
    x0 = np.zeros(model.size)
    samples, touches = model.residuals(x0, session)
    r = model.normalised(x0, session)
    statistic = float(r @ r)
    dof = len(r)
    J = model.jacobian(session)
    n = len(session.uv_px)
    fits = []
    for part, block in model.blocks.items():
        prior = prior_sd(part, robot.nq)
        fit, fitted_samples = fit_part(part, J[:, block], r, n, prior)
        L = model.null_factor(session)
        if L is None:
            fitted_m = fitted_samples * model.null.sample_axis_sds(n)
        else:  # back from the whitened residuals to metres
            fitted_m = (L @ -(J[:, block] @ fit.delta))[: 3 * n].reshape(n, 3)
        targeting = float(np.sqrt(np.mean(np.sum(fitted_m**2, axis=1)))) * 1e3
        multiples = float(np.max(np.abs(fit.delta) / prior)) if fit.delta.size else 0.0
        fits.append(replace(_with_targeting(fit, targeting), prior_multiples=multiples))
    failed, threshold, p_value, fits = union_test(statistic, dof, fits, false_alarm)
    verdict = "RECALIBRATE" if failed else "PASS"
    best = None
    if verdict != "PASS":
        # The most plausible single change; ties (e.g. probe mount and image transform without a
        # probe touch: the same residuals) go to PARTS' order.
        best = max(fits, key=lambda f: (f.log_evidence, -PARTS.index(f.part)))
    residual_rms = float(np.sqrt(np.mean(np.sum(samples**2, axis=1)))) * 1e3
    return CheckOutcome(
        method,
        false_alarm,
        statistic,
        dof,
        threshold,
        p_value,
        verdict,
        best,
        fits,
        model.null,
        samples * 1e3,
        touches * 1e3,
        list(session.sample_ids),
        [(t[0], t[1], t[2]) for t in session.touches],
        residual_rms,
    )


def _with_targeting(fit: PartFit, targeting_mm: float) -> PartFit:
    return replace(fit, targeting_mm=targeting_mm)


def _mm(spacing_m: FloatArray) -> str:
    return ",".join(f"{v * 1e3:g}" for v in spacing_m)


def calibrated_nominal_spacing(stored: ResultFile) -> FloatArray | None:
    """``(2,)`` the nominal spacing (m per pixel) of the session the result was calibrated on, if it
    says: a result updated from a check records it (``nominal_spacing_mm``: its image may no longer
    be the rigid methods'); else the rigid methods' spacing is the nominal one (the scaled methods
    estimate theirs), a whole-chain result keeping the sequential methods' beside its own."""

    def spacing_of(value: object) -> FloatArray | None:
        try:
            spacing = np.array(value, dtype=float) * 1e-3
        except (TypeError, ValueError):
            return None
        if spacing.shape == (2,) and np.all(np.isfinite(spacing)) and np.all(spacing > 0):
            return spacing
        return None

    recorded = spacing_of(stored.raw.get("nominal_spacing_mm"))
    if recorded is not None:
        return recorded
    for method in ("kabsch", "horn", "icp"):
        if method in stored.image:
            return stored.image[method].spacing_m
    sequential = stored.raw.get("sequential", {})
    spacings = sequential.get("spacing_mm", {}) if isinstance(sequential, dict) else {}
    for method in ("kabsch", "horn", "icp"):
        spacing = spacing_of(spacings.get(method) if isinstance(spacings, dict) else None)
        if spacing is not None:
            return spacing
    return None


def outcome_json(outcome: CheckOutcome, stored: ResultFile, session: CheckSession, robot: Robot) -> dict:
    """The verification record (format ``brachycal-verification/1``): every number finite."""
    part = outcome.part
    return {
        "format": "brachycal-verification/1",
        "date_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "result": {"file": stored.source, "sha256": stored.sha256, "method": outcome.method},
        "check_session": {"folder": session.folder, "inputs": session.inputs},
        "robot": robot.rig.name,
        "samples": len(outcome.sample_ids),
        "touches": len(outcome.touches),
        "test": {
            "statistic": "chi-square: sum of squared residuals, each coordinate over its null SD",
            "rule": "RECALIBRATE when the chi-square exceeds its quantile at 1 - false_alarm/2, or any part's "
            "explained chi-square (the part fitted alone; its rank in degrees of freedom) exceeds its quantile at "
            "1 - false_alarm/(2 P), P the parts tested: at most false_alarm in all (union bound)",
            "parts": {
                f.part: {"statistic": f.explained, "dof": f.rank, "threshold": f.threshold}
                for f in outcome.fits
                if f.rank > 0
            },
            "null_sd_mm": {
                "sample": outcome.null.sample_sd_m * 1e3,
                "sample_source": outcome.null.sample_source,
                "per_sample": {
                    sid: {"sd_mm": float(sd * 1e3), "calibration_sample": match}
                    for sid, sd, match in zip(
                        outcome.sample_ids,
                        outcome.null.sample_sds(len(outcome.sample_ids)),
                        outcome.null.pose_match or [None] * len(outcome.sample_ids),
                        strict=True,
                    )
                },
                **{f"touch_{t}": v * 1e3 for t, v in outcome.null.touch_sd_m.items()},
                "touch_source": outcome.null.touch_source,
                "sample_axis_scale": None
                if outcome.null.axis_scale is None
                else dict(zip(AXES, (float(v) for v in outcome.null.axis_scale), strict=True)),
                "covariance": outcome.null.covariance_source or "none: the residuals are taken as independent",
            },
            "value": outcome.statistic,
            "dof": outcome.dof,
            "false_alarm": outcome.false_alarm,
            "threshold": outcome.threshold,
            "p_value": outcome.p_value,
        },
        "verdict": outcome.verdict,
        "part": None if part is None else part.part,
        "indistinguishable_from": outcome.alternatives,
        "size": None if part is None else part.size_text(),
        "gross_error_suspected": part is not None and part.prior_multiples > GROSS_PRIOR_MULTIPLES,
        "targeting_if_ignored_mm": None if part is None else part.targeting_mm,
        "residual_rms_mm": outcome.residual_rms_mm,
        "hypotheses": [f.as_json(robot.joint_names) for f in outcome.fits],
        "sample_residuals_mm": {
            sid: [float(v) for v in e] for sid, e in zip(outcome.sample_ids, outcome.sample_residuals_mm, strict=True)
        },
        "touch_residuals_mm": [
            {"tool": t, "reference": ref, "trial": trial, "residual": [float(v) for v in e]}
            for (t, ref, trial), e in zip(outcome.touches, outcome.touch_residuals_mm, strict=True)
        ],
        "software": {"brachycal": __version__},
    }


def verdict_text(outcome: CheckOutcome) -> str:
    """The verdict as printed (one line for PASS; with the part, its size and the targeting error)."""
    tested = [f for f in outcome.fits if f.rank > 0]
    # The named part's own test, or on a pass the part nearest its threshold.
    named = [f for f in tested if outcome.part is not None and f.part == outcome.part.part]
    top = named[0] if named else max(tested, key=lambda f: f.explained / f.threshold) if tested else None
    part_text = f"; {top.part} alone {top.explained:.1f} on {top.rank}, threshold {top.threshold:.1f}" if top else ""
    head = (
        f"chi-square {outcome.statistic:.1f} on {outcome.dof} degrees of freedom, threshold {outcome.threshold:.1f}"
        f"{part_text}; {100 * outcome.false_alarm:g} % false alarms in all (p = {outcome.p_value:.3g}); "
        f"sample residuals {outcome.residual_rms_mm:.2f} mm RMS, noise included"
    )
    if outcome.part is None:
        return f"PASS: the calibration still holds ({head})"
    part = outcome.part
    if part.prior_multiples > GROSS_PRIOR_MULTIPLES:
        return (
            f"RECALIBRATE: no small change of one part explains the check (the closest, the {part.part}, would "
            f"have to move {part.prior_multiples:.0f} times its prior SD): check the session's labels, touches and "
            f"annotations, then recalibrate ({head})"
        )
    plausible = (
        ""
        if part.p_remaining >= outcome.false_alarm
        else " (no single part explains it all: more than one may have moved)"
    )
    name = part.part
    if outcome.alternatives:
        name = (
            " or ".join([part.part, *outcome.alternatives]) + " (the check cannot tell them apart; a probe touch can)"
        )
    return (
        f"RECALIBRATE: the {name} most likely moved, by {part.size_text()}; ignored, it would cost "
        f"{part.targeting_mm:.2f} mm of targeting error (RMS over the check poses){plausible} ({head})"
    )
