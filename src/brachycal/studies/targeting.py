"""End-to-end targeting error on the twin: what the clinic needs.

For targets spread through the prostate cube: the probe (physically) images the target; the
software maps the target's pixel through the calibrated chain, with the *nominal* robot model
and the *reported* joints, to a point in ``base_link``; the needle is commanded there through
the nominal model with the calibrated needle tip (the torso and the probe arm hold still); the
physical robot executes those joints, and we measure how far its needle tip lands from the
physical target. Annotation noise is left out (a planned target's pixel is exact), so the
figure isolates the calibration and the robot. Leave-one-out figures cannot see what all
samples share (a tool offset, a wrong pixel scale); this can.

Held-out configurations (``torso_turn_rad``): each aim starts from the nearest sample pose with
the torso turned, so both arms reach the same targets in postures the calibration never saw
(3° moves the elbows by a few centimetres). A calibration that absorbed the robot's own error
into its tools at the sample poses loses accuracy there; one that identified the robot should not.
The torso is the rig's shared joint (``robot.rig.shared_joints``, the first if several: the
SDA10F's ``torso_joint_b1``). A robot without one (Baxter's torso is fixed, a cell of two arms
on a table has none) has no turn that moves both arms together: a non-zero turn is refused there
(:class:`~brachycal.errors.InputError`), and ``brachycal study`` reports its held-out figures as
NaN ("no torso" in its table).

Any robot: the probe arm images, the needle arm moves (``robot.rig``'s arms and flanges).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.chain import ChainFit
from brachycal.calibration.chain.uncertainty import inside_ellipsoid, landing_covariance
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.result import Calibration, calibration_args
from brachycal.calibration.sequential.image_to_probe import predict_base
from brachycal.errors import InputError, SolverError
from brachycal.imaging.pixels import image_points, pixels
from brachycal.model.ik import solve_ik
from brachycal.model.names import NEEDLE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform
from brachycal.simulation.twin import STREAMS, Twin, streams
from brachycal.validate import MAX_TARGETS, check_int, check_range

#: Largest torso turn of the held-out configurations: beyond ~0.1 rad the arms leave the reach of
#: some targets from the sample poses' neighbourhood.
MAX_TORSO_TURN_RAD = 0.2


@dataclass(frozen=True)
class TargetingResult:
    """Targets (``(M, 3)``, physical, in the robot's base frame), where the needle landed, and the error stats.

    ``uv_px (M, 2)`` and ``q_read (M, nq)`` are the pixel and the read joints (probe imaging, needle
    arm at its start pose) each target was computed from — what a prediction of the error uses.
    """

    targets_m: FloatArray
    landed_m: FloatArray
    stats: ErrorStats
    uv_px: FloatArray
    q_read: FloatArray


def torso_index(robot: Robot) -> int | None:
    """Index of the joint the held-out turn moves: the rig's first shared joint, ``None`` without one."""
    shared = robot.rig.shared_indices
    return shared[0] if shared else None


def random_targets(twin: Twin, n: int) -> FloatArray:
    """``(n, 3)`` points uniformly inside the planning cube, in the robot's base frame (seeded by the twin)."""
    spec = twin.config.spec
    rng = streams(twin.config.seed)[STREAMS[-1]]
    offsets = rng.uniform(-0.5, 0.5, size=(n, 3)) * spec.edge_m
    return spec.cube_centre_m + offsets @ spec.image_axes().T


def targeting_error(
    twin: Twin,
    calibration: Calibration,
    *args: Any,
    n_targets: int = 50,
    software: Robot | None = None,
    torso_turn_rad: float = 0.0,
) -> TargetingResult:
    """Needle landing error over ``n_targets`` targets for one ``calibration`` (see the module docstring).

    ``targeting_error(twin, calibration, n_targets=50, *, software=None, torso_turn_rad=0.0)``; the
    loose form ``(twin, T_ER_Ntip, T_EL_Ptip, image, n_targets, ...)`` works for one release
    (deprecated). ``n_targets`` may also come positionally after the calibration.

    ``software`` is the robot model the software computes and commands with (default: the
    nominal URDF; a calibration that corrects the robot passes its corrected model).
    ``torso_turn_rad`` turns the torso of every start pose (held-out configurations, module
    docstring; within ±0.2 rad; only on a robot with a shared joint).

    Raises:
        SolverError: a target is out of reach from all five nearest sample poses.
        InputError: a non-zero torso turn on a robot without a shared joint.
    """
    calibration, rest = calibration_args("targeting_error", calibration, args)
    if len(rest) > 1:
        raise TypeError("targeting_error() takes (twin, calibration, n_targets)")
    n_targets = rest[0] if rest else n_targets
    check_int(n_targets, "number of targets", low=1, high=MAX_TARGETS)
    check_range(torso_turn_rad, "torso turn", low=-MAX_TORSO_TURN_RAD, high=MAX_TORSO_TURN_RAD, unit="rad")
    torso = torso_index(twin.nominal)
    if torso is None and torso_turn_rad != 0.0:
        raise InputError(
            f"robot {twin.nominal.rig.name!r} has no joint shared by both arms (no torso): held-out "
            "configurations by a torso turn need one"
        )
    aim = _Aim(twin, software or twin.nominal, calibration)
    targets = random_targets(twin, n_targets)
    landed = np.empty_like(targets)
    uv = np.empty((n_targets, 2))
    q_read = np.empty((n_targets, twin.nominal.nq))
    # Each target starts from the sample poses whose needle tips were nearest (planned poses).
    sample_tips = twin.physical.fk(NEEDLE_TIP, twin.true_samples_q)[:, :3, 3]
    for k, target in enumerate(targets):
        starts = np.argsort(np.linalg.norm(sample_tips - target, axis=1))[:5]
        for attempt, nearest in enumerate(starts):
            q_start = twin.true_samples_q[nearest].copy()
            if torso is not None:
                q_start[torso] += torso_turn_rad
            try:
                landed[k], uv[k], q_read[k] = aim.land(target, q_start)
                break
            except SolverError:  # unreachable from this start: try the next (input errors propagate)
                if attempt == len(starts) - 1:
                    raise
    return TargetingResult(targets, landed, ErrorStats.between(targets, landed), uv, q_read)


class _Aim:
    """One calibration used to image a target, compute it, and send the needle there."""

    def __init__(self, twin: Twin, software: Robot, calibration: Calibration) -> None:
        self.twin, self.software = twin, software
        self.T_EL_Ptip, self.image = calibration.T_EL_Ptip, calibration.image
        self.nominal_cal = software.with_tool_transform(NEEDLE_TIP, calibration.T_ER_Ntip)
        rig = twin.nominal.rig
        self.needle_arm, self.probe_arm = rig.needle_arm_indices, rig.probe_arm_indices
        self.probe_flange = rig.probe_flange
        spec = twin.config.spec
        self.R_image = spec.image_axes()
        self.direction = spec.needle_pose(spec.cube_centre_m)[:3, 2]
        self.read_rng = np.random.default_rng(np.random.SeedSequence(twin.config.seed).spawn(len(STREAMS) + 1)[-1])
        # Joints may use their whole range here (the plan kept margins; a target between grid
        # points can need a little more); no random restarts far from the start pose.
        self.ik = functools.partial(solve_ik, margin=0.0, restarts=0)

    def land(self, target: FloatArray, q_start: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Where the physical needle tip lands when aimed at ``target`` (metres, base_link), the
        target's pixel, and the joints read (probe arm imaging it, needle arm at its start)."""
        twin, spec, truth = self.twin, self.twin.config.spec, self.twin.truth
        # The probe images the target at the pixel the cube geometry puts it (true spacing).
        offset = self.R_image.T @ (target - spec.cube_centre_m)
        uv = np.asarray(spec.centre_px) + pixels(offset, truth.spacing_m)[0]
        origin = target - self.R_image @ image_points(uv, truth.spacing_m)[0]
        q_true = self.ik(twin.physical, US_IMAGE, make_transform(self.R_image, origin), q_start, self.probe_arm)
        q_read = q_true.copy()
        if twin.config.encoder_noise:
            q_read += self.read_rng.normal(scale=twin.config.encoder_sd_rad, size=q_true.shape)
        # The software's estimate of the target, and the needle commanded onto it: the roll as in
        # the start pose, the axis turned onto the insertion direction.
        p_software = predict_base(self.image, self.software.fk(self.probe_flange, q_read), self.T_EL_Ptip, uv[None])[0]
        R_needle = self.nominal_cal.fk(NEEDLE_TIP, q_start)[:3, :3]
        turn, _ = Rotation.align_vectors([self.direction], [R_needle[:, 2]])
        T_command = make_transform(turn.as_matrix() @ R_needle, p_software)
        arm = self.needle_arm
        q_command = self.ik(self.nominal_cal, NEEDLE_TIP, T_command, q_read, arm)
        q_executed = q_true.copy()
        q_executed[arm] = q_command[arm]
        q_seen = q_read.copy()
        q_seen[arm] = q_command[arm]
        return twin.physical.fk(NEEDLE_TIP, q_executed)[:3, 3], uv, q_seen


@dataclass(frozen=True)
class LandingCheck:
    """A whole-chain fit's landing error on the twin against its own prediction (mm, ``base_link``).

    Attributes:
        actual_rms_mm: RMS over the targets of where the needle landed minus the target.
        predicted_rms_mm: RMS over the same targets of the predicted landing error
            (:func:`~brachycal.calibration.chain.uncertainty.landing_covariance` at each target's pixel
            and read joints: the session's noise, the stated robot accuracy and the joint readings'
            noise when aiming).
        inside: ``(M,)`` whether each target's error lies inside its predicted ``level`` ellipsoid.
    """

    actual_rms_mm: float
    predicted_rms_mm: float
    inside: np.ndarray

    @property
    def ratio(self) -> float:
        """Actual over predicted RMS landing error: 1 when the prediction is honest."""
        return self.actual_rms_mm / self.predicted_rms_mm


def landing_check(
    twin: Twin, fit: ChainFit, n_targets: int = 20, *, software: Robot | None = None, level: float = 0.95
) -> LandingCheck:
    """Aim at ``n_targets`` targets with ``fit``'s calibration (:func:`targeting_error`; ``software``
    the robot model it commands with, default the nominal URDF: an identified fit passes its corrected
    robot) and compare the landing errors with the fit's predicted covariance there."""
    robot = software or twin.nominal
    hit = targeting_error(twin, fit.calibration(), n_targets, software=robot)
    C = landing_covariance(fit, robot, twin.session.spacing_m, hit.q_read, hit.uv_px)
    error = hit.landed_m - hit.targets_m
    actual = float(np.sqrt(np.mean(np.sum(error**2, axis=1))))
    predicted = float(np.sqrt(np.mean(np.trace(C, axis1=1, axis2=2))))
    return LandingCheck(actual * 1e3, predicted * 1e3, inside_ellipsoid(error, C, level))
