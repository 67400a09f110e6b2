"""Digital twin of a calibration session: a "physical" robot and tools with a known truth.

Every error source is a switch of :class:`TwinConfig` with a documented default and its own random
stream (switching one off leaves the others' draws unchanged).

Design: ``docs/design/twin.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.data.session import Session, Touches
from brachycal.errors import InputError
from brachycal.imaging.pixels import SCANNER_SOUND_SPEED_M_S, image_points
from brachycal.model.ik import solve_ik
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.planning import PlanSpec, SectorFOV, plan_poses
from brachycal.se3 import FloatArray, make_transform, transform_points
from brachycal.simulation.exact import (
    SessionTruth,
    axes_moves,
    axes_start,
    default_truth,
    touch,
    touch_tools,
)
from brachycal.simulation.settings import (
    MAX_ANNOTATION_SD_PX,
    MAX_OUTLIER_RATE,
    ROBOT_ERROR_LEVELS,
    SOUND_SPEED_RANGE_M_S,
    WATER_SOUND_SPEED_M_S,
)
from brachycal.validate import MAX_IMAGE_PX, check_int, check_range, check_seed, check_vector

#: The twin's random streams, one per error source (and the targets of the targeting error).
STREAMS = ("robot", "tools", "jog", "encoder", "beam", "annotation", "outliers", "targets")

#: Range of each numeric noise setting of :class:`TwinConfig` (all SDs >= 0). The upper ends are
#: typo guards some 100 times the defaults: beyond them the touches and IK of the twin are no
#: longer a calibration session (millimetres of link error, centimetres of jog).
_RANGES: dict[str, tuple[float, float, str]] = {
    "link_offset_sd_m": (0.0, 1e-2, "m"),
    "link_tilt_sd_rad": (0.0, 0.1, "rad"),
    "joint_offset_sd_rad": (0.0, 0.1, "rad"),
    "encoder_sd_rad": (0.0, 1e-2, "rad"),
    "jog_sd_m": (0.0, 1e-2, "m"),
    "annotation_sd_px": (0.0, MAX_ANNOTATION_SD_PX, "px"),
    "sound_speed_m_s": (*SOUND_SPEED_RANGE_M_S, "m/s"),
    "beam_thickness_m": (0.0, 1e-2, "m"),
    "outlier_rate": (0.0, MAX_OUTLIER_RATE, ""),
    "tool_offset_sd_m": (0.0, 0.05, "m"),
    "tool_tilt_sd_rad": (0.0, 0.2, "rad"),
}
_SWITCHES = (
    "kinematic_error",
    "encoder_noise",
    "jog_error",
    "annotation_noise",
    "sound_speed",
    "out_of_plane",
    "outliers",
)


class _RobotWorkspace(PlanSpec):
    """:class:`PlanSpec`'s defaults standing for "the simulated robot's own workspace": the default
    of :attr:`TwinConfig.spec`, told apart by its type (which, unlike an object's identity, survives
    pickling and copying: a config sent to a worker process still means the robot's workspace)."""


def _robot_workspace() -> PlanSpec:
    return _RobotWorkspace()


def spec_for(nominal: Robot, config: TwinConfig) -> PlanSpec:
    """The plan spec a twin of ``nominal`` uses: ``config.spec`` if one was given; left at its default,
    the robot's own workspace (:meth:`PlanSpec.for_robot`), or :class:`PlanSpec`'s defaults
    themselves when the workspace is theirs (the SDA10F's: its directions agree to 1e-12, but
    normalising the description's insertion direction moves its last bit, and the committed example
    was planned with :class:`PlanSpec`'s).
    """
    if not isinstance(config.spec, _RobotWorkspace):
        return config.spec
    own, defaults = PlanSpec.for_robot(nominal), PlanSpec()
    same = all(
        np.allclose(getattr(own, name), getattr(defaults, name), rtol=0.0, atol=1e-12)
        for name in ("cube_centre_m", "insertion_dir", "image_depth_dir", "image_lateral_dir")
    )
    return defaults if same else own


@dataclass(frozen=True)
class TwinConfig:
    """Noise sources of the twin (see the module docstring for what each one models).

    Every setting is checked on construction: the switches must be ``True``/``False``, the seed
    in [0, 2**32), each SD finite and within its range (``_RANGES``: from 0 up to about 100
    times its default), the sound speed in [1000, 2000] m/s, the outlier rate in [0, 0.5], the
    outlier sizes 0 <= low <= high px, 1 to 100 trials. ``spec`` left at its default means the
    simulated robot's own workspace (:func:`spec_for`); the :class:`Twin` holds the resolved one.

    Raises:
        InputError: naming the setting, its range and the value given.
    """

    seed: int = 0
    kinematic_error: bool = True
    link_offset_sd_m: float = 3e-5
    link_tilt_sd_rad: float = np.radians(0.003)
    joint_offset_sd_rad: float = np.radians(0.003)
    encoder_noise: bool = True
    encoder_sd_rad: float = 2e-5
    jog_error: bool = True
    jog_sd_m: float = 5e-5
    annotation_noise: bool = True
    annotation_sd_px: float = 1.0
    sound_speed: bool = True
    sound_speed_m_s: float = WATER_SOUND_SPEED_M_S
    out_of_plane: bool = True
    beam_thickness_m: float = 0.6e-3
    outliers: bool = False
    outlier_rate: float = 0.10
    outlier_px: tuple[float, float] = (15.0, 40.0)
    tool_offset_sd_m: float = 2e-3
    tool_tilt_sd_rad: float = np.radians(1.0)
    trials: int = 3
    spec: PlanSpec = field(default_factory=_robot_workspace)

    def __post_init__(self) -> None:
        check_seed(self.seed, "twin seed")
        for name in _SWITCHES:
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputError(f"twin setting {name} must be True or False, got {getattr(self, name)!r}")
        for name, (low, high, unit) in _RANGES.items():
            check_range(getattr(self, name), f"twin setting {name}", low=low, high=high, unit=unit)
        low, high = check_vector(self.outlier_px, "twin setting outlier_px", 2, low=0.0, high=MAX_IMAGE_PX, unit="px")
        if not low <= high:
            raise InputError(f"twin setting outlier_px must be (low, high) with low <= high, got {self.outlier_px}")
        check_int(self.trials, "twin setting trials", low=1, high=100)
        if not isinstance(self.spec, PlanSpec):
            raise InputError(f"twin setting spec must be a PlanSpec, got {type(self.spec).__name__}")

    def without_noise(self) -> TwinConfig:
        """The same set-up with every noise source off (the tools keep their offsets from nominal)."""
        return replace(
            self,
            kinematic_error=False,
            encoder_noise=False,
            jog_error=False,
            annotation_noise=False,
            sound_speed=False,
            out_of_plane=False,
            outliers=False,
        )

    def with_robot_error(self, level: str) -> TwinConfig:
        """The same set-up with the physical robot off its URDF by a named level
        (:data:`ROBOT_ERROR_LEVELS`).

        Raises:
            InputError: an unknown level.
        """
        if level not in ROBOT_ERROR_LEVELS:
            raise InputError(f"unknown robot-error level {level!r}; choose from {', '.join(ROBOT_ERROR_LEVELS)}")
        shift, tilt, zero = ROBOT_ERROR_LEVELS[level]
        return replace(self, link_offset_sd_m=shift, link_tilt_sd_rad=tilt, joint_offset_sd_rad=zero)

    @property
    def axial_scale(self) -> float:
        """True depth per displayed depth: sound speed in the medium over the scanner's assumption."""
        return self.sound_speed_m_s / SCANNER_SOUND_SPEED_M_S if self.sound_speed else 1.0


@dataclass(frozen=True, repr=False)
class Twin:
    """A simulated session and everything needed to judge a calibration of it.

    Attributes:
        session: what the lab would record (reported joints, annotated pixels).
        truth: the true tool and image transforms, the true pixel spacing, the reference tips.
        physical: the physical robot: perturbed kinematics with the true tool frames.
        nominal: the URDF model the software uses.
        config: the noise settings.
        true_samples_q: ``(N, nq)`` true joints of the image samples.
        out_of_plane_m: ``(N,)`` the needle tip's distance from the image plane per sample.
        outlier: ``(N,)`` which annotations are gross mistakes.
    """

    session: Session
    truth: SessionTruth
    physical: Robot
    nominal: Robot
    config: TwinConfig
    true_samples_q: FloatArray
    out_of_plane_m: FloatArray
    outlier: np.ndarray

    def __repr__(self) -> str:
        outliers = int(np.count_nonzero(self.outlier))
        return "\n".join(
            [
                f"Twin (seed {self.config.seed}): a simulated session with its truth "
                f"({outliers} gross annotation mistakes)",
                *("  " + line for line in repr(self.session).splitlines()),
            ]
        )


def streams(seed: int) -> dict[str, np.random.Generator]:
    """The twin's random streams for ``seed`` (:data:`STREAMS`): one generator per error source, so
    switching one source off leaves the others' draws unchanged."""
    children = np.random.SeedSequence(seed).spawn(len(STREAMS))
    return {name: np.random.default_rng(child) for name, child in zip(STREAMS, children, strict=True)}


def _small_motion(rng: np.random.Generator, shift_sd: float, tilt_sd: float) -> FloatArray:
    return make_transform(
        Rotation.from_rotvec(rng.normal(scale=tilt_sd, size=3)).as_matrix(), rng.normal(scale=shift_sd, size=3)
    )


def physical_kinematics(nominal: Robot, config: TwinConfig, rng: np.random.Generator) -> Robot:
    """The nominal robot with every joint's origin moved a little (fixed for this robot)."""
    if not config.kinematic_error:
        return nominal
    origins, zeros = {}, {}
    for name in nominal.joint_names:  # per joint: shift and tilt, then its zero offset
        origins[name] = nominal.joint_origin(name) @ _small_motion(
            rng, config.link_offset_sd_m, config.link_tilt_sd_rad
        )
        zeros[name] = rng.normal(scale=config.joint_offset_sd_rad)
    return nominal.with_joint_origins(origins).with_joint_offsets(zeros)


def _truth(nominal: Robot, config: TwinConfig, rng: np.random.Generator) -> SessionTruth:
    base = default_truth(nominal)
    nudge = lambda T: T @ _small_motion(rng, config.tool_offset_sd_m, config.tool_tilt_sd_rad)  # noqa: E731
    return replace(
        base,
        T_ER_Ntip=nudge(nominal.tool_transform(NEEDLE_TIP)[1]),
        T_EL_Ptip=nudge(nominal.tool_transform(PROBE_TIP)[1]),
        T_Ptip_I=nudge(nominal.tool_transform(US_IMAGE)[1]),
        spacing_m=base.nominal_spacing_m * [1.0, config.axial_scale],
    )


def simulate(nominal: Robot, config: TwinConfig = TwinConfig()) -> Twin:
    """Simulate one calibration session of ``nominal`` (any robot with a rig: ``nominal.rig``).

    The returned twin's ``config`` holds the plan spec used (:func:`spec_for`).

    Raises:
        SolverError: a pose of the set-up is unreachable for the physical robot.
        InputError: the robot has no rig (a bare URDF that is not the SDA10F's).
    """
    rig = nominal.rig
    config = replace(config, spec=spec_for(nominal, config))
    rng = streams(config.seed)
    truth = _truth(nominal, config, rng["tools"])
    physical = truth.robot(physical_kinematics(nominal, config, rng["robot"]))

    def read(q: FloatArray) -> FloatArray:
        return q + rng["encoder"].normal(scale=config.encoder_sd_rad, size=q.shape) if config.encoder_noise else q

    def jog() -> FloatArray:
        return rng["jog"].normal(scale=config.jog_sd_m, size=3) if config.jog_error else np.zeros(3)

    q_home = rig.ready
    tools = touch_tools(nominal)
    touches = {}
    for reference, p_R in (("rtip1", truth.p_R_Rtip1), ("rtip2", truth.p_R_Rtip2)):
        for tool, frame, arm in tools:
            q_trials = [
                touch(physical, frame, arm, p_R + jog(), k, config.trials, q_home, config.seed)
                for k in range(config.trials)
            ]
            touches[tool, reference] = Touches(np.arange(1, config.trials + 1), read(np.array(q_trials)))

    starts = axes_start(nominal)
    axes = {
        tool: {
            point: read(q) for point, q in axes_moves(physical, frame, arm, starts[tool], q_home, config.seed).items()
        }
        for tool, frame, arm in tools[1:]
    }

    plan = plan_poses(nominal, config.spec)
    n = len(plan.poses)
    offsets = rng["beam"].uniform(-0.5, 0.5, size=n) * config.beam_thickness_m if config.out_of_plane else np.zeros(n)
    true_q_rows: list[FloatArray] = []
    uv_rows: list[tuple[float, float]] = []
    for pose, e in zip(plan.poses, offsets, strict=True):
        q = pose.q.copy()
        tip = physical.fk(NEEDLE_TIP, q)[:3, 3]
        R_image = physical.fk(US_IMAGE, q)[:3, :3]
        u, v = pose.point.uv_px
        origin = tip - R_image @ image_points((u, v), truth.spacing_m, e)[0]
        # The adjustment is small; the physical arm may use its whole range (the plan kept margins).
        q = solve_ik(
            physical, US_IMAGE, make_transform(R_image, origin), q, rig.probe_arm_indices, margin=0.0, restarts=0
        )
        true_q_rows.append(q)
        uv_rows.append((u, v))
    true_q, uv = np.array(true_q_rows), np.array(uv_rows, dtype=float)
    annotated = uv.copy()
    if config.annotation_noise:
        annotated += rng["annotation"].normal(scale=config.annotation_sd_px, size=uv.shape)
    outlier = np.zeros(n, dtype=bool)
    if config.outliers:
        outlier = rng["outliers"].random(n) < config.outlier_rate
        angle = rng["outliers"].uniform(0, 2 * np.pi, size=n)
        size = rng["outliers"].uniform(*config.outlier_px, size=n)
        annotated[outlier] += (size[:, None] * np.column_stack([np.cos(angle), np.sin(angle)]))[outlier]
    session = Session(
        spacing_m=truth.nominal_spacing_m.copy(),
        size_px=truth.size_px.copy(),
        p_ER_Mtip=truth.p_ER_Mtip.copy(),
        touches=touches,
        axes=axes,
        sample_ids=[pose.point.name for pose in plan.poses],
        samples_q=read(true_q),
        uv_px=annotated,
        joint_names=nominal.joint_names,
        sector=config.spec.fov.as_sector() if isinstance(config.spec.fov, SectorFOV) else None,
    )
    return Twin(session, truth, physical, nominal, config, true_q, offsets, outlier)


def tip_in_image(twin: Twin, k: int) -> FloatArray:
    """Where sample ``k``'s needle tip truly is in the image frame, metres (diagnostic)."""
    q = twin.true_samples_q[k]
    T_R_I = twin.physical.fk(US_IMAGE, q)
    return transform_points(np.linalg.inv(T_R_I), twin.physical.fk(NEEDLE_TIP, q)[:3, 3])
