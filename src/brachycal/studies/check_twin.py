"""The pre-procedure check on the twin: calibrate a twin session, change something, check.

One trial (:func:`check_trial`): the twin's calibration session (:func:`~brachycal.simulation.simulate`)
is calibrated and stored as a result file; then the set-up is changed (:data:`CHANGES`: nothing,
the probe holder remounted, the needle bent or replaced, another speed of sound, a joint's zero
drifted) and a check session is recorded at the check poses (``plan check``'s choice from the
same grid): the needle arm goes to its planned joints, the probe is adjusted until the needle tip
shows near its planned pixel, the joints are read (encoder noise) and the tip annotated (1 px),
the tip within the beam's thickness of the plane, as in the calibration session; optionally the
needle and the probe, or the probe alone, touch ``rtip1`` once (jog error). Each check draws its noise from its
own seed, so many checks can be made against one calibration.

The true targeting effect of a change is measured too: the RMS over the check poses of the change
of the noise-free check residual (where a target imaged there would be missed, minus where it was
missed before the change).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from brachycal.calibration import calibrate, read_result, write_result
from brachycal.calibration.robot_accuracy import DEFAULT_ROBOT_ACCURACY, RobotAccuracy
from brachycal.calibration.session.chain_report import calibrate_chain
from brachycal.calibration.verify.check import CheckSession, chain_model, check_calibration
from brachycal.calibration.verify.update import update_refusal, updated_result
from brachycal.data.session import Session, Touches
from brachycal.data.session import write_check_session as write_check_folder
from brachycal.imaging.pixels import SCANNER_SOUND_SPEED_M_S, image_points
from brachycal.io import OutputSet, write_json
from brachycal.model.ik import solve_ik
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.planning import plan_poses
from brachycal.planning.check_poses import (
    DEFAULT_CHECK_POSES,
    DEFAULT_TOUCHES,
    nominal_calibration,
    plan_check,
    touch_choice,
)
from brachycal.se3 import FloatArray, make_transform
from brachycal.simulation.exact import touch, touch_tools
from brachycal.simulation.recording import Recording, Stop, record_stops
from brachycal.simulation.twin import Twin, TwinConfig, simulate

if TYPE_CHECKING:
    from brachycal.calibration.session.result_file import ResultFile


@dataclass(frozen=True)
class Change:
    """A change of the set-up after calibration (each zero: no change).

    Attributes:
        probe_shift_m / probe_tilt_rad: the probe holder remounted: the probe (and its image) moved
            on the flange by this translation and rotation, in random directions.
        needle_bend_m: the needle tip moved perpendicular to the needle (a bent tip), random direction.
        needle_axial_m: the tip moved along the needle (another needle: its tip elsewhere).
        sound_speed_m_s: the medium's speed of sound during the check (None: the calibration's).
        joint_drift_rad: zero offset drift of ``drift_joint``.
        image_shift_m / image_tilt_rad: the probe re-seated in its holder: the image moved on the
            probe tip (which stays), random directions.
    """

    name: str
    probe_shift_m: float = 0.0
    probe_tilt_rad: float = 0.0
    needle_bend_m: float = 0.0
    needle_axial_m: float = 0.0
    sound_speed_m_s: float | None = None
    joint_drift_rad: float = 0.0
    drift_joint: str = "arm_left_joint_2_l"
    image_shift_m: float = 0.0
    image_tilt_rad: float = 0.0


#: The changes the validation page's table measures.
CHANGES: dict[str, Change] = {
    c.name: c
    for c in (
        Change("unchanged"),
        Change("probe remounted 0.5 mm / 0.5 deg", probe_shift_m=0.5e-3, probe_tilt_rad=np.radians(0.5)),
        Change("probe remounted 1 mm / 1 deg", probe_shift_m=1e-3, probe_tilt_rad=np.radians(1.0)),
        Change("needle tip bent 0.3 mm", needle_bend_m=0.3e-3),
        Change("another needle (tip 3 mm along it)", needle_axial_m=3e-3),
        Change("speed of sound 1482 -> 1510 m/s", sound_speed_m_s=1510.0),
        Change("probe-arm joint 2 zero drift 0.03 deg", joint_drift_rad=np.radians(0.03)),
        Change("probe re-seated (image 0.5 mm / 0.5 deg)", image_shift_m=0.5e-3, image_tilt_rad=np.radians(0.5)),
    )
}


@dataclass(frozen=True)
class TwinSettings:
    """Settings of a check twin other than the defaults the check was designed on (each None: the
    twin's default, :class:`~brachycal.simulation.twin.TwinConfig`, at the named robot-error level).

    Attributes:
        annotation_px: annotation noise SD per image axis, pixels.
        robot_translation_m / robot_rotation_rad: each joint origin's error as a 3-D norm (RMS):
            per axis it is this over √3 (the zero offset's SD is the rotation's over √3 too).
        touch_turn_rad: each check touch is re-done by hand at a new orientation, turned by up to
            this (a uniform angle about a random axis) from the calibration's first approach.
        cad_close: the tools and the image within 0.2 mm / 0.1° SD of the URDF's nominal frames
            (a CAD-close URDF) instead of 2 mm / 1°.
        stated: the robot accuracy stated at calibration is the twin's true per-axis level (else the
            default statement, a well-built arm).
        beam_thickness_m: the needle tip within half of this off the image plane (0: in it).
        every_trial: the check's touches follow the calibration's protocol (every trial of each
            touching tool on both reference tips) instead of one touch of ``rtip1``.
    """

    annotation_px: float | None = None
    robot_translation_m: float | None = None
    robot_rotation_rad: float | None = None
    touch_turn_rad: float = 0.0
    cad_close: bool = False
    stated: bool = True
    every_trial: bool = False
    beam_thickness_m: float | None = None

    def config(self, seed: int, robot_error: str) -> TwinConfig:
        """The twin's configuration for ``seed`` at ``robot_error`` with these settings."""
        config = TwinConfig(seed=seed).with_robot_error(robot_error)
        changes: dict[str, Any] = {}
        if self.annotation_px is not None:
            changes["annotation_sd_px"] = self.annotation_px
        if self.robot_translation_m is not None:
            changes["link_offset_sd_m"] = self.robot_translation_m / np.sqrt(3.0)
        if self.robot_rotation_rad is not None:
            changes["link_tilt_sd_rad"] = self.robot_rotation_rad / np.sqrt(3.0)
            changes["joint_offset_sd_rad"] = self.robot_rotation_rad / np.sqrt(3.0)
        if self.beam_thickness_m is not None:
            changes["beam_thickness_m"] = self.beam_thickness_m
        if self.cad_close:
            changes.update(tool_offset_sd_m=2e-4, tool_tilt_sd_rad=float(np.radians(0.1)))
        return replace(config, **changes)

    def label(self) -> str:
        """The settings as a person reads them (the defaults left out)."""
        words = []
        if self.annotation_px is not None:
            words.append(f"{self.annotation_px:g} px")
        if self.robot_translation_m is not None or self.robot_rotation_rad is not None:
            mm = (self.robot_translation_m or 0.0) * 1e3
            deg = float(np.degrees(self.robot_rotation_rad or 0.0))
            words.append(f"robot {mm:g} mm / {deg:g} deg")
        if self.touch_turn_rad:
            words.append(f"touches turned <= {np.degrees(self.touch_turn_rad):g} deg")
        if self.cad_close:
            words.append("CAD-close URDF")
        if self.beam_thickness_m is not None:
            words.append(f"beam {self.beam_thickness_m * 1e3:g} mm")
        if not self.stated:
            words.append("accuracy not stated")
        if self.every_trial:
            words.append("every touch trial")
        return ", ".join(words) or "defaults"


def _unit(rng: np.random.Generator, perpendicular_to: FloatArray | None = None) -> FloatArray:
    v = rng.normal(size=3)
    if perpendicular_to is not None:
        v -= (v @ perpendicular_to) * perpendicular_to
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class ChangedSetup:
    """The physical set-up after a change: robot with true tools, true pixel spacing."""

    physical: Robot
    spacing_m: FloatArray


def changed_setup(twin: Twin, change: Change, rng: np.random.Generator) -> ChangedSetup:
    """The twin's physical robot and spacing after ``change`` (random directions from ``rng``)."""
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    truth = twin.truth
    T_ER_Ntip = truth.T_ER_Ntip.copy()
    axis = T_ER_Ntip[:3, 2]  # the needle runs along its tip frame's z
    T_ER_Ntip[:3, 3] += change.needle_bend_m * (T_ER_Ntip[:3, :3] @ _unit(rng, np.array([0.0, 0.0, 1.0])))
    T_ER_Ntip[:3, 3] += change.needle_axial_m * axis
    remount = make_transform(
        Rotation.from_rotvec(change.probe_tilt_rad * _unit(rng)).as_matrix(), change.probe_shift_m * _unit(rng)
    )
    spacing = truth.spacing_m.copy()
    if change.sound_speed_m_s is not None:
        spacing = truth.nominal_spacing_m * [1.0, change.sound_speed_m_s / SCANNER_SOUND_SPEED_M_S]
    # The twin's physical robot already carries the true tools: only the changed ones are rewritten.
    robot = twin.physical
    if change.needle_bend_m or change.needle_axial_m:
        robot = robot.with_tool_transform(NEEDLE_TIP, T_ER_Ntip)
    if change.probe_shift_m or change.probe_tilt_rad:
        robot = robot.with_tool_transform(PROBE_TIP, truth.T_EL_Ptip @ remount)
    if change.image_shift_m or change.image_tilt_rad:
        reseat = make_transform(
            Rotation.from_rotvec(change.image_tilt_rad * _unit(rng)).as_matrix(), change.image_shift_m * _unit(rng)
        )
        robot = robot.with_tool_transform(US_IMAGE, truth.T_Ptip_I @ reseat)
    if change.joint_drift_rad:
        robot = robot.with_joint_offsets({change.drift_joint: change.joint_drift_rad})
    return ChangedSetup(robot, spacing)


def record_check(
    twin: Twin,
    setup: ChangedSetup,
    q_planned: FloatArray,
    uv_planned: FloatArray,
    rng: np.random.Generator,
    *,
    touches: str = DEFAULT_TOUCHES,
    touch_turn_rad: float = 0.0,
    every_trial: bool = False,
) -> tuple[CheckSession, FloatArray]:
    """A check session recorded on ``setup`` at the planned poses ``(N, nq)`` / pixels ``(N, 2)``,
    with the twin's noise settings, and single touches of ``rtip1`` by the tools of ``touches``
    (a :data:`~brachycal.planning.check_poses.TOUCH_CHOICES` key), each turned by up to
    ``touch_turn_rad`` from the calibration's first approach (:class:`TwinSettings`); with
    ``every_trial``, the calibration's touch protocol instead (every trial on both reference tips,
    each turned so); also returns
    the true joints ``(N, nq)`` of its samples."""
    config, physical, rig = twin.config, setup.physical, twin.nominal.rig

    def read(q: FloatArray) -> FloatArray:
        return q + rng.normal(scale=config.encoder_sd_rad, size=q.shape) if config.encoder_noise else q

    true_q, uv = [], []
    for q0, (u, v) in zip(q_planned, uv_planned, strict=True):
        e = rng.uniform(-0.5, 0.5) * config.beam_thickness_m if config.out_of_plane else 0.0
        true_q.append(_adjust(setup, q0, np.array([u, v]), e, rig.probe_arm_indices))
        uv.append((u, v))
    Q, UV = np.array(true_q), np.array(uv, dtype=float)
    if config.annotation_noise:
        UV = UV + rng.normal(scale=config.annotation_sd_px, size=UV.shape)
    touched = []
    tools = touch_choice(touches)
    tips = {"rtip1": twin.truth.p_R_Rtip1}
    if every_trial:
        tips["rtip2"] = twin.truth.p_R_Rtip2
    for reference, p_R in tips.items():
        for tool, frame, arm in touch_tools(twin.nominal)[1:]:
            if tool not in tools:
                continue
            for k in range(config.trials if every_trial else 1):
                jog = rng.normal(scale=config.jog_sd_m, size=3) if config.jog_error else np.zeros(3)
                q = touch(physical, frame, arm, p_R + jog, k, config.trials, rig.ready, config.seed)
                if touch_turn_rad:
                    q = _turned_touch(physical, frame, arm, q, rng.uniform(-1.0, 1.0) * touch_turn_rad * _unit(rng))
                touched.append((tool, reference, k + 1, read(q)))
    ids = [f"check{k + 1}" for k in range(len(Q))]
    session = CheckSession("twin check", twin.truth.nominal_spacing_m, twin.truth.size_px, ids, read(Q), UV, touched)
    return session, Q


def _turned_touch(robot: Robot, frame: str, arm: list[int], q: FloatArray, rotvec: FloatArray) -> FloatArray:
    """The touch at joints ``q`` re-done with the tool turned by ``rotvec`` (rad, in ``base_link``)
    about its tip, which stays on the reference tip."""
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy.spatial, only the turned touches need it)

    T = robot.fk(frame, q)
    target = make_transform(Rotation.from_rotvec(rotvec).as_matrix() @ T[:3, :3], T[:3, 3])
    return solve_ik(robot, frame, target, q, arm, margin=0.0, restarts=0)


def noise_free_residuals_mm(
    stored: ResultFile,
    method: str,
    robot: Robot,
    twin: Twin,
    setup: ChangedSetup,
    q_planned: FloatArray,
    uv_planned: FloatArray,
) -> FloatArray:
    """``(N, 3)`` check residuals of the stored calibration with no noise, mm: on ``setup`` the
    probe is adjusted until the needle tip lies in the image plane at its planned pixel (as when
    recording), and the joints are read exactly. Each is the targeting error at that pose."""
    q = np.array(
        [
            _adjust(setup, q0, uv, 0.0, twin.nominal.rig.probe_arm_indices)
            for q0, uv in zip(q_planned, uv_planned, strict=True)
        ]
    )
    session = CheckSession("", setup.spacing_m, np.zeros(2), [], q, np.asarray(uv_planned, float))
    samples, _ = chain_model(stored, method, robot).residuals(np.zeros(17 + robot.nq), session)
    return samples * 1e3


def _adjust(setup: ChangedSetup, q0: FloatArray, uv: FloatArray, e: float, probe_arm: list[int]) -> FloatArray:
    """The probe arm moved (from ``q0``) so that the needle tip shows at pixel ``uv``, ``e`` metres
    off the image plane, on the physical set-up (the image keeps its orientation)."""
    physical = setup.physical
    tip = physical.fk(NEEDLE_TIP, q0)[:3, 3]
    R_image = physical.fk(US_IMAGE, q0)[:3, :3]
    origin = tip - R_image @ image_points(uv, setup.spacing_m, e)[0]
    # The adjustment is small; the physical arm may use its whole range (the plan kept margins).
    return solve_ik(physical, US_IMAGE, make_transform(R_image, origin), q0, probe_arm, margin=0.0, restarts=0)


@dataclass(frozen=True)
class TrialOutcome:
    """One check's verdict and what the change did to targeting (mm, RMS over the check poses of the
    noise-free residuals): ``targeting_before_mm`` the calibration's own error before the change,
    ``targeting_ignored_mm`` after it, ``targeting_change_mm`` of their difference; with an update,
    ``targeting_updated_mm`` the updated result's error, or ``update_refusal`` why none was made."""

    change: str
    seed: int
    check_seed: int
    verdict: str
    part: str | None
    statistic: float
    threshold: float
    targeting_change_mm: float
    fitted_targeting_mm: float | None
    update_refusal: str | None = None
    targeting_updated_mm: float | None = None
    targeting_before_mm: float = 0.0
    targeting_ignored_mm: float = 0.0


class CalibratedTwin:
    """A twin session, its calibration (a result file in ``folder``) and the check poses, with the
    single touches of ``touches`` (a :data:`~brachycal.planning.check_poses.TOUCH_CHOICES` key).
    With ``pose_nulls`` (default) each check is given the calibration session, for each pose's own
    null SD (:func:`~brachycal.calibration.verify.check.with_calibration_poses`)."""

    def __init__(
        self,
        seed: int,
        robot: Robot,
        folder: str | os.PathLike[str],
        *,
        robot_error: str = "well-built",
        method: str = "chain",
        count: int = DEFAULT_CHECK_POSES,
        touches: str = DEFAULT_TOUCHES,
        result_path: str | os.PathLike[str] | None = None,
        pose_nulls: bool = True,
        settings: TwinSettings = TwinSettings(),
    ) -> None:
        config = settings.config(seed, robot_error)
        self.settings = settings
        self.twin = twin = simulate(robot, config)
        path = Path(result_path) if result_path else Path(folder) / f"result_{robot_error}_{seed}.json"
        accuracy = DEFAULT_ROBOT_ACCURACY
        if settings.stated:  # the lab states its arm's accuracy (per axis, as the twin draws it)
            accuracy = RobotAccuracy(
                config.link_offset_sd_m, config.link_tilt_sd_rad, config.encoder_sd_rad, source="the twin's level"
            )
        if method == "chain":
            initial = calibrate(twin.session, robot, ("kabsch", "scaled_uv"))  # kabsch: the nominal spacing
            report = calibrate_chain(twin.session, robot, initial, robot_accuracy=accuracy)
            write_result(initial, path, force=True, chain=report, robot=robot)
        else:
            write_result(calibrate(twin.session, robot), path, force=True, robot=robot)
        self.stored = read_result(path)
        self.method = self.stored.method(None)
        self.robot = self.stored.software_robot(robot)
        full = plan_poses(robot, twin.config.spec)
        self.check_plan = plan_check(full, robot, self.stored.calibration(self.method), count=count, touches=touches)
        self.touches = touches
        self.pose_nulls = pose_nulls
        self.q_planned = np.array([p.q for p in self.check_plan.plan.poses])
        self.uv_planned = np.array([p.point.uv_px for p in self.check_plan.plan.poses])
        self._before: FloatArray | None = None

    def trial(
        self,
        change: Change,
        check_seed: int,
        *,
        touches: str | None = None,
        false_alarm: float = 0.05,
        update: bool = False,
    ) -> TrialOutcome:
        """One check of ``change`` with noise drawn from ``check_seed`` (``touches``: the plan's
        unless given). With ``update``, a failed check that may update the result
        (:func:`~brachycal.calibration.verify.update.update_refusal`) does, and the outcome has the
        targeting error of the updated result on the changed set-up (RMS of its noise-free check
        residuals, mm); else why not."""
        rng = np.random.default_rng([self.twin.config.seed, check_seed, 7])
        unchanged = ChangedSetup(self.twin.physical, self.twin.truth.spacing_m)
        setup = changed_setup(self.twin, change, rng)
        session, _ = record_check(
            self.twin,
            setup,
            self.q_planned,
            self.uv_planned,
            rng,
            touches=touches or self.touches,
            touch_turn_rad=self.settings.touch_turn_rad,
            every_trial=self.settings.every_trial,
        )
        calibration = self.twin.session if self.pose_nulls else None
        outcome = check_calibration(
            self.stored, self.method, self.robot, session, false_alarm=false_alarm, calibration=calibration
        )
        if self._before is None:
            self._before = noise_free_residuals_mm(
                self.stored, self.method, self.robot, self.twin, unchanged, self.q_planned, self.uv_planned
            )
        before = self._before
        after = noise_free_residuals_mm(
            self.stored, self.method, self.robot, self.twin, setup, self.q_planned, self.uv_planned
        )
        change_mm = float(np.sqrt(np.mean(np.sum((after - before) ** 2, axis=1))))
        refusal, updated_mm = None, None
        if update and outcome.verdict == "RECALIBRATE":
            refusal, updated_mm = self._update(outcome, session, setup)
        part = outcome.part
        return TrialOutcome(
            change.name,
            self.twin.config.seed,
            check_seed,
            outcome.verdict,
            None if part is None else part.part,
            outcome.statistic,
            outcome.threshold,
            change_mm,
            None if part is None else part.targeting_mm,
            refusal,
            updated_mm,
            float(np.sqrt(np.mean(np.sum(before**2, axis=1)))),
            float(np.sqrt(np.mean(np.sum(after**2, axis=1)))),
        )

    def _update(self, outcome, session: CheckSession, setup: ChangedSetup) -> tuple[str | None, float | None]:
        """``(why not, None)`` or ``(None, targeting error of the updated result in mm)``."""

        refusal = update_refusal(outcome)
        if refusal is not None:
            return refusal, None
        with tempfile.TemporaryDirectory() as folder:
            updated = read_result(
                write_json(Path(folder) / "updated.json", updated_result(self.stored, outcome, session))
            )
        residuals = noise_free_residuals_mm(
            updated, self.method, self.robot, self.twin, setup, self.q_planned, self.uv_planned
        )
        return None, float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def check_trial(
    seed: int,
    change: str,
    robot: Robot,
    folder: str | os.PathLike[str],
    *,
    check_seed: int = 0,
    robot_error: str = "well-built",
) -> TrialOutcome:
    """One trial: calibrate twin ``seed``, apply ``change`` (a :data:`CHANGES` name), check."""
    return CalibratedTwin(seed, robot, folder, robot_error=robot_error).trial(CHANGES[change], check_seed)


def write_check_session(
    session: CheckSession,
    template: Twin,
    folder: str | os.PathLike[str],
    robot: Robot,
    *,
    force: bool = False,
    outputs: OutputSet | None = None,
) -> Path:
    """Write a check session folder (:func:`~brachycal.data.session.write_check_session`: ``session.toml``
    with ``template``'s top-model tip, ``samples.csv``, ``touches.csv``; all or nothing, with
    ``outputs`` they join that set)."""
    grouped: dict[tuple[str, str], list[tuple[int, FloatArray]]] = {}
    for tool, reference, trial, q in session.touches:
        grouped.setdefault((tool, reference), []).append((trial, q))
    folder_session = Session(
        spacing_m=session.spacing_m,
        size_px=session.size_px,
        p_ER_Mtip=template.truth.p_ER_Mtip,
        touches={
            key: Touches(np.array([t for t, _ in rows]), np.array([q for _, q in rows]))
            for key, rows in grouped.items()
        },
        axes={},
        sample_ids=session.sample_ids,
        samples_q=session.samples_q,
        uv_px=session.uv_px,
        joint_names=tuple(robot.joint_names),
    )
    return write_check_folder(folder_session, folder, force=force, outputs=outputs)


#: The twin's check recordings (``brachycal demo --recording --check``): folder, change, check seed.
CHECK_RECORDINGS: tuple[tuple[str, str, int], ...] = (
    ("check_recording", "unchanged", 1),
    ("check_recording_remounted", "probe remounted 1 mm / 1 deg", 2),
)
#: A check recording starts a day after its calibration's (the morning of a procedure), seconds.
CHECK_RECORDING_LATER_S = 86400.0


def check_recording(
    rec: Recording,
    robot: Robot,
    change: Change,
    check_seed: int,
    *,
    count: int = DEFAULT_CHECK_POSES,
    touches: str = DEFAULT_TOUCHES,
) -> Recording:
    """The check before a procedure on the twin that ``rec`` recorded, as a lab records it.

    The poses are those ``brachycal plan check`` picks from the recording's plan (``count`` of them,
    the robot's nominal tools), the set-up is the twin's after ``change`` (random directions and
    noise drawn from ``check_seed``, as :meth:`CalibratedTwin.trial` draws them); the robot first
    touches ``rtip1`` with the tools of ``touches`` (one mark each), then stops at each pose with the
    probe adjusted until the needle tip shows at its planned pixel (one annotated frame each). The
    joint log starts a day after ``rec``'s, with ``rec``'s rate, speeds and encoder noise; its plan
    is the check's."""
    twin = rec.twin  # its encoder noise is off: record_check gives the true joints, the log adds the noise
    check = plan_check(
        rec.plan, robot, nominal_calibration(robot, twin.config.spec.spacing_m), count=count, touches=touches
    )
    q_planned = np.array([p.q for p in check.plan.poses])
    uv_planned = np.array([p.point.uv_px for p in check.plan.poses])
    rng = np.random.default_rng([twin.config.seed, check_seed, 7])
    setup = changed_setup(twin, change, rng)
    session, q_true = record_check(twin, setup, q_planned, uv_planned, rng, touches=touches)
    stops = [Stop(q, "touch", tool, reference) for tool, reference, _, q in session.touches]
    stops += [Stop(q, "frame", uv_px=uv) for q, uv in zip(q_true, session.uv_px, strict=True)]
    settings = replace(
        rec.recording, unannotated_frames=0, start_time_s=rec.recording.start_time_s + CHECK_RECORDING_LATER_S
    )
    return record_stops(robot, stops, twin, check.plan, rec.config, settings, stream=(check_seed,))
