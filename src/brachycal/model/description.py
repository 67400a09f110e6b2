"""Robot descriptions: which robot, which arm holds which tool, where the tools sit, where it works.

A robot description is a small TOML file (``docs/robots.md`` documents it key by key) that names a
URDF — or several single-arm URDFs mounted on one base — and says what brachycal must know beyond
the kinematics: the needle arm and the probe arm (their joints and flange links), the joints both
arms share (the SDA10F's torso), joints held still (a head pan, a gripper), the tool frames and how
they are mounted nominally, the ready stance, the collision pairs to ignore (MoveIt SRDFs) and the
sample workspace (the 40 mm cube and the probe and needle directions of the paper's set-up).

:func:`load_description` reads one, checks every name against the URDF and every number, builds the
URDF text in memory (the tool frames appended as fixed joints, single arms merged under one base,
frozen joints made fixed, ``package://`` mesh paths resolved) and returns a frozen
:class:`RobotDescription` holding the :class:`~brachycal.model.robot.Robot`. Nothing is written:
the URDFs of example-robot-data are read from its installed share folder and never copied.

A description names either a dual-arm rig (``[needle_arm]`` and ``[probe_arm]``: what the paper's
calibration needs) or any arms (``[[arm]]`` tables: a base link, a flange link, an optional tool
frame; what the commands about one arm need). :func:`load_robot` also takes a plain URDF file.

Bundled descriptions (``src/brachycal/robots``): the dual-arm rigs ``sda10f`` (the default,
equivalent to :mod:`brachycal.model.names`), ``baxter`` and ``ur5_pair``; the single arms
``panda``, ``ur5`` and ``ur10`` (example-robot-data's URDFs). A file path loads any other.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, check_input_file
from brachycal.model.description_file import (
    BUNDLED_ROBOTS,
    DEFAULT_ROBOT,
    SINGLE_ARM_ROBOTS,
    arms_of,
    bundled_description_path,
    example_robot_data_share,
    read_description_file,
    rig_of,
)
from brachycal.model.rig import Arm, ArmDescription, Rig, Workspace
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

__all__ = [
    "BUNDLED_ROBOTS",
    "DEFAULT_ROBOT",
    "SINGLE_ARM_ROBOTS",
    "URDF_SUFFIXES",
    "RobotDescription",
    "load_description",
    "load_robot",
]

#: File name endings :func:`load_robot` takes as a plain URDF (any other path is a description).
URDF_SUFFIXES = (".urdf", ".xml")


@dataclass(frozen=True)
class RobotDescription:
    """A described robot: its arms, its :class:`Rig` when it is a dual-arm rig, and the model that
    carries both (``robot.arms``, ``robot.rig``).

    The rig's fields and properties read through (``description.needle_arm_indices`` is
    ``description.rig.needle_arm_indices``); for a description of ``[[arm]]`` tables they refuse,
    as :attr:`rig` does.

    Attributes:
        name: short name, as ``--robot`` takes it.
        source: the TOML file.
        summary: one line about the robot (may be empty).
        base: the base link (the paper's R).
        arms: its arms (a dual-arm rig's: the needle arm and the probe arm).
        robot: the kinematic model with the tool frames (its URDF text is the built one), carrying
            the arms and the rig.
    """

    name: str
    source: Path
    summary: str
    base: str
    arms: tuple[Arm, ...]
    robot: Robot = field(repr=False, compare=False)

    @property
    def rig(self) -> Rig:
        """Everything beyond the kinematics of a dual-arm rig.

        Raises:
            InputError: the description names ``[[arm]]`` tables, not a needle arm and a probe arm.
        """
        return self.robot.rig

    @property
    def dual_arm(self) -> bool:
        """Whether it is a dual-arm rig (has :attr:`rig`)."""
        return self.robot.has_rig

    @property
    def needle_arm(self) -> ArmDescription:
        """The arm holding the needle."""
        return self.rig.needle_arm

    @property
    def probe_arm(self) -> ArmDescription:
        """The arm holding the probe."""
        return self.rig.probe_arm

    @property
    def shared_joints(self) -> tuple[str, ...]:
        """Joints moving both flanges."""
        return self.rig.shared_joints

    @property
    def shared_ready(self) -> tuple[float, ...]:
        """Their ready stance."""
        return self.rig.shared_ready

    @property
    def frozen_joints(self) -> Mapping[str, float]:
        """Joints held fixed, with their values."""
        return self.rig.frozen_joints

    @property
    def mimic_joints(self) -> Mapping[str, str]:
        """Published joints copying a coordinate."""
        return self.rig.mimic_joints

    @property
    def controller_joint_names(self) -> tuple[str, ...]:
        """The controller's order."""
        return self.rig.controller_joint_names

    @property
    def disabled_pairs(self) -> frozenset[frozenset[str]]:
        """Link pairs never checked."""
        return self.rig.disabled_pairs

    @property
    def mounts(self) -> Mapping[str, FloatArray]:
        """``T_base_root`` of each mounted arm, by prefix."""
        return self.rig.mounts

    @property
    def workspace(self) -> Workspace:
        """The sample cube and directions."""
        return self.rig.workspace

    @property
    def needle_flange(self) -> str:
        """The needle arm's flange link."""
        return self.rig.needle_flange

    @property
    def probe_flange(self) -> str:
        """The probe arm's flange link."""
        return self.rig.probe_flange

    @property
    def needle_arm_indices(self) -> list[int]:
        """Needle arm's joint indices."""
        return self.rig.needle_arm_indices

    @property
    def probe_arm_indices(self) -> list[int]:
        """Probe arm's joint indices."""
        return self.rig.probe_arm_indices

    @property
    def shared_indices(self) -> list[int]:
        """Shared joints' indices."""
        return self.rig.shared_indices

    @property
    def ready(self) -> FloatArray:
        """``(nq,)`` ready stance (a fresh array)."""
        return self.rig.ready

    @property
    def tool_frame_parents(self) -> dict[str, str]:
        """Tool frame → link."""
        return self.rig.tool_frame_parents

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The configuration's columns, in order (the robot's)."""
        return self.robot.joint_names

    @property
    def nq(self) -> int:
        return self.robot.nq


# --- loading --------------------------------------------------------------------------------
@functools.lru_cache(maxsize=16)
def _load_cached(path: Path, mtime_ns: int) -> RobotDescription:
    return _load(path)


def load_description(name_or_path: str | os.PathLike[str] = DEFAULT_ROBOT) -> RobotDescription:
    """Load a robot description: a bundled name (:data:`BUNDLED_ROBOTS`) or a ``.toml`` file.

    Loaded descriptions are cached by the description file and its modification time (building
    one parses the URDF and the SRDFs: 0.03 s for the SDA10F, 0.04 s for the UR5 cell, 0.06 s for Baxter);
    an edited URDF under an unchanged description is not noticed within one process.

    Raises:
        InputError: one line naming the file and the key: an unknown robot name, a file that cannot
            be read or is not TOML, a missing or unknown key, a name the URDF does not have, a joint
            in no arm, a ready stance of the wrong length or outside the limits, a bad transform.
    """
    text = os.fspath(name_or_path)
    if text in BUNDLED_ROBOTS or text in SINGLE_ARM_ROBOTS:
        path = bundled_description_path(text)
    elif os.sep in text or "/" in text or text.endswith(".toml"):
        path = Path(text)
    else:
        raise InputError(
            f"unknown robot {text!r}: bundled robots are {', '.join(BUNDLED_ROBOTS + SINGLE_ARM_ROBOTS)}, "
            "or give a .toml description or a .urdf file"
        )
    try:
        resolved = path.resolve(strict=True)
        mtime = resolved.stat().st_mtime_ns
    except OSError as exc:
        raise InputError(f"cannot read robot description ({exc.strerror})", file=path) from None
    check_input_file(path, max_bytes=MAX_DOCUMENT_BYTES)
    return _load_cached(resolved, mtime)


def _load(path: Path) -> RobotDescription:
    file = read_description_file(path)
    robot = Robot(file.urdf_xml, base_dir=file.base_dir, source=str(path))
    arms: tuple[Arm, ...]
    if file.dual_arm:
        rig = rig_of(file, robot.model, robot.joint_names, robot.lower, robot.upper)
        robot, arms = robot.with_rig(rig), rig.arms
    else:
        arms = arms_of(file, robot.joint_names)
        robot = robot.with_arms(arms, file.name)
    return RobotDescription(file.name, path, file.summary, file.base, arms, robot)


def load_robot(name_or_path: str | os.PathLike[str] = DEFAULT_ROBOT) -> Robot:
    """The robot model of ``--robot``: a bundled description's name, a description file (``.toml``),
    or a plain URDF file (:data:`URDF_SUFFIXES`; ``example-robot-data:robots/…`` names one of that
    package's), loaded as :meth:`Robot.load <brachycal.model.robot.Robot.load>` loads it.

    A plain URDF has no arms named (``robot.arms`` is empty unless it is the SDA10F's) and no rig of
    another robot: the commands about a dual-arm rig refuse it, ``model`` and ``fk`` take it.

    Raises:
        InputError: as :func:`load_description`, or a URDF that cannot be read or loaded.
    """
    text = os.fspath(name_or_path)
    if text.startswith("example-robot-data:"):
        path = example_robot_data_share() / text.removeprefix("example-robot-data:")
        if not path.is_file():
            raise InputError(f"no file {text.removeprefix('example-robot-data:')} in example-robot-data ({path})")
        return Robot.load(path)
    if text.lower().endswith(URDF_SUFFIXES):
        return Robot.load(text)
    return load_description(text).robot
