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

Bundled descriptions (``src/brachycal/robots``): ``sda10f`` (the default, equivalent to
:mod:`brachycal.model.names`), ``baxter`` and ``ur5_pair``. A file path loads any other.
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
    bundled_description_path,
    read_description_file,
    rig_of,
)
from brachycal.model.rig import ArmDescription, Rig, Workspace
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

__all__ = ["BUNDLED_ROBOTS", "DEFAULT_ROBOT", "RobotDescription", "load_description"]


@dataclass(frozen=True)
class RobotDescription:
    """A robot brachycal can calibrate: its :class:`Rig` and the model that carries it (``robot.rig``).

    The rig's fields and properties read through (``description.needle_arm_indices`` is
    ``description.rig.needle_arm_indices``).

    Attributes:
        rig: everything beyond the kinematics.
        robot: the kinematic model with the tool frames (its URDF text is the built one), carrying ``rig``.
    """

    rig: Rig
    robot: Robot = field(repr=False, compare=False)

    @property
    def name(self) -> str:
        """Short name, as ``--robot`` takes it."""
        return self.rig.name

    @property
    def source(self) -> Path:
        """The TOML file."""
        return self.rig.source

    @property
    def summary(self) -> str:
        """One line about the robot."""
        return self.rig.summary

    @property
    def base(self) -> str:
        """The base link (the paper's R)."""
        return self.rig.base

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
    if text in BUNDLED_ROBOTS:
        path = bundled_description_path(text)
    elif os.sep in text or "/" in text or text.endswith(".toml"):
        path = Path(text)
    else:
        raise InputError(
            f"unknown robot {text!r}: bundled robots are {', '.join(BUNDLED_ROBOTS)}, or give a .toml file"
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
    rig = rig_of(file, robot.model, robot.joint_names, robot.lower, robot.upper)
    return RobotDescription(rig=rig, robot=robot.with_rig(rig))
