"""Arms of any robot (:class:`Arm`: a base link, a flange link, an optional tool frame) and a
dual-arm robot's rig: which arm holds which tool, the ready stance, what a controller publishes,
which link pairs never collide, where it works (:class:`Rig`), read from a robot description
(:mod:`brachycal.model.description`). Configurations are radians (metres for prismatic joints);
poses ``T_base_frame`` in the rig's base, metres.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from brachycal.se3 import FloatArray

__all__ = ["TOOL_FRAMES", "Arm", "ArmDescription", "Rig", "Workspace"]

#: The tool frames of CONVENTIONS.md, each with what it is mounted on: the needle arm's flange
#: (``"needle_flange"``), the probe arm's flange (``"probe_flange"``) or another tool frame.
TOOL_FRAMES: Mapping[str, str] = MappingProxyType(
    {
        "needle_tip": "needle_flange",
        "top_model_tip": "needle_flange",
        "probe_tip": "probe_flange",
        "us_image": "probe_tip",
    }
)


@dataclass(frozen=True)
class Arm:
    """One arm of any robot: the chain from a base link to a flange link, with an optional tool frame.

    What a single-arm estimator needs (``T_base_flange`` and ``T_base_tool`` from forward kinematics,
    the coordinates that move them); a dual-arm rig's two arms are arms too (:attr:`Rig.arms`).

    Attributes:
        name: short name (``arm``, ``needle_arm``), as a description names it.
        base: the link poses are measured in (the robot's base, or a link above the flange).
        flange: the link tools mount on (z out of the flange, ROS-Industrial's ``tool0`` convention).
        tool: a frame rigidly on the flange (a touch probe's ball, a marker), or ``None``.
        joints: the configuration coordinates that move the flange relative to the base, root to flange.
    """

    name: str
    base: str
    flange: str
    tool: str | None
    joints: tuple[str, ...]


@dataclass(frozen=True)
class ArmDescription:
    """One arm: its flange link and its own joints (shoulder to wrist), with the ready stance.

    Attributes:
        flange: link the tools mount on (z out of the flange, ROS-Industrial's ``tool0`` convention).
        joints: the arm's configuration coordinates, shoulder to wrist (joints no other arm moves).
        ready: ``(len(joints),)`` ready stance of these joints, radians (metres for prismatic joints).
    """

    flange: str
    joints: tuple[str, ...]
    ready: tuple[float, ...]


@dataclass(frozen=True)
class Workspace:
    """Where the samples are taken, in the description's base frame (the planner's inputs).

    Attributes:
        cube_centre_m: ``(3,)`` centre of the 40 mm sample cube (the prostate), metres.
        insertion_dir: ``(3,)`` unit needle direction (the needle tip frame's z axis).
        image_depth_dir: ``(3,)`` unit direction of the image's +v (depth) at the reference probe pose.
        image_lateral_dir: ``(3,)`` unit direction of the image's +u, perpendicular to the depth.
    """

    cube_centre_m: tuple[float, float, float]
    insertion_dir: tuple[float, float, float]
    image_depth_dir: tuple[float, float, float]
    image_lateral_dir: tuple[float, float, float]


@dataclass(frozen=True)
class Rig:
    """What brachycal knows about a dual-arm robot beyond its kinematics: which arm holds which tool,
    the ready stance, what a controller publishes, which link pairs never collide, where it works.

    Every :class:`~brachycal.model.robot.Robot` carries one (:attr:`Robot.rig`): the planner, the
    twin and the output files ask it instead of the SDA10F's constants (:mod:`brachycal.model.names`).
    Configurations are ``(nq,)`` arrays in :attr:`joint_names` order (the robot's, Pinocchio's
    depth-first order of the built URDF), radians (metres for prismatic joints); poses are
    ``T_base_frame`` in :attr:`base`, metres.

    Attributes:
        name: short name (``sda10f``), as ``--robot`` takes it.
        source: the description's TOML file.
        summary: one line about the robot, for ``brachycal model``.
        base: the base link, root of the model (the paper's R).
        joint_names: the configuration's columns, in order (the robot's).
        needle_arm, probe_arm: the arm holding the needle (and the top model) and the arm holding the probe.
        shared_joints: coordinates that move both flanges (the SDA10F's torso); may be empty.
        shared_ready: ``(len(shared_joints),)`` their ready stance.
        frozen_joints: URDF joints made fixed at a value (rad or m): no configuration column.
        mimic_joints: joints a controller publishes that only copy a coordinate (multiplier 1,
            offset 0) and are not coordinates themselves: name → the coordinate they copy.
        controller_joint_names: the controller's joint order (a permutation of :attr:`joint_names`).
        disabled_pairs: link pairs never checked for collision (read from the SRDFs; empty means
            every pair of non-adjacent links with geometry is checked).
        mounts: for a cell of single arms, ``T_base_root`` ``(4, 4)`` of each arm's root link, by prefix.
        workspace: the sample cube and the probe and needle directions.
    """

    name: str
    source: Path
    summary: str
    base: str
    joint_names: tuple[str, ...]
    needle_arm: ArmDescription
    probe_arm: ArmDescription
    shared_joints: tuple[str, ...]
    shared_ready: tuple[float, ...]
    frozen_joints: Mapping[str, float]
    mimic_joints: Mapping[str, str]
    controller_joint_names: tuple[str, ...]
    disabled_pairs: frozenset[frozenset[str]] = field(repr=False)
    mounts: Mapping[str, FloatArray] = field(repr=False, compare=False)
    workspace: Workspace

    # Pickled with a robot (to worker processes): the read-only mappings travel as plain dicts.
    _MAPPINGS = ("frozen_joints", "mimic_joints", "mounts")

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        for key in self._MAPPINGS:
            state[key] = dict(state[key])
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        for key in self._MAPPINGS:
            state[key] = MappingProxyType(state[key])
        for T in state["mounts"].values():
            T.flags.writeable = False
        self.__dict__.update(state)

    @property
    def nq(self) -> int:
        return len(self.joint_names)

    @property
    def needle_flange(self) -> str:
        return self.needle_arm.flange

    @property
    def probe_flange(self) -> str:
        return self.probe_arm.flange

    def _indices(self, names: tuple[str, ...]) -> list[int]:
        return [self.joint_names.index(n) for n in names]

    @property
    def needle_arm_indices(self) -> list[int]:
        """Indices into a configuration of the needle arm's joints, shoulder to wrist (the SDA10F's ``RIGHT_ARM``)."""
        return self._indices(self.needle_arm.joints)

    @property
    def probe_arm_indices(self) -> list[int]:
        """Indices of the probe arm's joints, shoulder to wrist (the SDA10F's ``LEFT_ARM``)."""
        return self._indices(self.probe_arm.joints)

    @property
    def shared_indices(self) -> list[int]:
        """Indices of the shared joints (moving them moves both flanges)."""
        return self._indices(self.shared_joints)

    @property
    def ready(self) -> FloatArray:
        """``(nq,)`` ready stance in :attr:`joint_names` order (a fresh, writable array)."""
        q = np.empty(self.nq)
        q[self.needle_arm_indices] = self.needle_arm.ready
        q[self.probe_arm_indices] = self.probe_arm.ready
        q[self.shared_indices] = self.shared_ready
        return q

    @property
    def arms(self) -> tuple[Arm, Arm]:
        """The needle arm and the probe arm as :class:`Arm` (named ``needle_arm``, ``probe_arm``), from
        :attr:`base` to each flange: the shared joints, then the arm's own, with the needle and probe tips."""
        return (
            Arm("needle_arm", self.base, self.needle_flange, "needle_tip", self.shared_joints + self.needle_arm.joints),
            Arm("probe_arm", self.base, self.probe_flange, "probe_tip", self.shared_joints + self.probe_arm.joints),
        )

    @property
    def tool_frame_parents(self) -> dict[str, str]:
        """Each tool frame with the link it is rigidly attached to (``names.TOOL_FRAME_PARENTS`` for the SDA10F)."""
        flanges = {"needle_flange": self.needle_flange, "probe_flange": self.probe_flange}
        return {frame: flanges.get(mount, mount) for frame, mount in TOOL_FRAMES.items()}
