"""The robot model: a URDF with tool frames, kinematics on Pinocchio.

A :class:`Robot` is immutable. Its URDF text is the single source of truth: the Pinocchio model
is built from it, a calibrated robot is a new :class:`Robot` whose tool joints carry new
``<origin>`` values (:meth:`Robot.with_tool_transform`), and :meth:`Robot.write_urdf` writes that
text back out for ROS/MoveIt (:meth:`Robot.with_joint_origins` moves a copy of the Pinocchio model
directly and writes the text on first use: identification evaluates many such robots).

A robot carries its rig (:attr:`Robot.rig`, a :class:`~brachycal.model.rig.Rig`): which arm
holds which tool, the ready stance, the collision pairs, the controller's joint order, the
workspace. A description sets it (:func:`~brachycal.model.description.load_description`);
:meth:`Robot.load` gives the SDA10F's; every ``with_*`` robot keeps it.

Configurations are arrays in :attr:`Robot.joint_names` order (for the bundled SDA10F:
:data:`brachycal.model.names.JOINT_NAMES`, torso then left arm then right arm), in radians
(metres for prismatic joints): one number per degree of freedom, as joint logs carry them. A
continuous joint is one unbounded angle, a mimic joint has no column (it follows its leader, as
the URDF says); :mod:`brachycal.model.joints` lists every joint type.
Poses are ``T_base_frame`` arrays of shape ``(4, 4)`` or ``(N, 4, 4)``, metres.

Forward kinematics has two back ends, chosen once per model when it is built
(:attr:`Robot.fk_backend`): ``"batch"``, the vectorised NumPy path of
:mod:`brachycal.model.batch_fk`, when it can compile every joint (revolute, continuous,
prismatic: serial arms, the SDA10F); otherwise ``"pinocchio"``, Pinocchio's own evaluation one
configuration at a time (mimic, planar, floating joints). Both give the same poses to 1e-12 m.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import io
import os
import sys
import threading
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, MAX_MESH_BYTES, check_input_file, read_input_bytes, read_input_text
from brachycal.io import atomic_open, bundled
from brachycal.model import urdf_text
from brachycal.model.batch_fk import BatchForwardKinematics
from brachycal.model.description_file import bundled_description_path, read_description_file, rig_of
from brachycal.model.joints import ONE_AXIS, Coordinates, UnsupportedJoint
from brachycal.model.rig import Arm, Rig
from brachycal.se3 import FloatArray, inverse, make_transform

if TYPE_CHECKING:
    import mujoco

#: Configurations evaluated per block by the batch path: bounds the working memory (~2 MiB
#: besides the output) and paces progress reports; 4096 measured fastest of 1024 to 20,000.
CHUNK = 4096


def bundled_urdf_path() -> Path:
    """Path of the bundled ``sda10f.urdf`` (inside an installed wheel, or in the source tree)."""
    return bundled("urdf", "sda10f.urdf")


@functools.cache
def sda10f_rig() -> Rig:
    """The bundled SDA10F's rig (``robots/sda10f.toml``, equivalent to :mod:`brachycal.model.names`), read once:
    the one :func:`~brachycal.model.description.load_description` gives, checked against the model of
    the description's own URDF."""
    file = read_description_file(bundled_description_path("sda10f").resolve())
    robot = Robot(file.urdf_xml, base_dir=file.base_dir, source=str(file.source))
    return rig_of(file, robot.model, robot.joint_names, robot.lower, robot.upper)


class Robot:
    """Kinematic model of a robot with its tool frames.

    Args:
        urdf_xml: URDF text.
        base_dir: folder that relative mesh paths in the URDF are resolved against.
        source: name used in error messages (usually the file path).
        rig: which arm holds which tool, the ready stance, the collision pairs, the workspace
            (:class:`~brachycal.model.rig.Rig`); ``None``: none (:attr:`rig` refuses).

    Raises:
        InputError: the text is not a URDF that Pinocchio can load.
    """

    def __init__(
        self,
        urdf_xml: str,
        *,
        base_dir: str | os.PathLike[str],
        source: str = "<urdf>",
        rig: Rig | None = None,
    ) -> None:
        self._rig = rig
        #: The arms a description of ``[[arm]]`` tables names (:meth:`with_arms`), and its name; None: none.
        self._arms: tuple[Arm, ...] | None = None
        self._described_as: str | None = None
        #: For :meth:`load`: the SDA10F's rig, fetched on first use of :attr:`rig` (reading the
        #: description costs 0.03 s, which commands that never ask for it should not pay).
        self._sda10f_rig_on_demand = False
        self._tree: ET.Element | None = urdf_text.parse(urdf_xml, source)
        self._text: str | None = urdf_xml
        #: The text the robot was read from, and the joint origins ``T_parent_joint`` moved since on
        #: the model directly (:meth:`with_joint_origins`); :attr:`urdf_xml` writes them in on first use.
        self._read_text = urdf_xml
        self._moved: dict[str, FloatArray] = {}
        #: Joint origins read from :attr:`urdf_xml` so far (:meth:`joint_origin`).
        self._read_origins: dict[str, FloatArray] = {}
        self.base_dir = Path(base_dir)
        self.source = source
        failure: Exception | None = None
        with urdfdom_errors() as errors:
            try:
                # mimic=True: a mimic joint follows its leader, as the URDF says, not an axis of its own.
                self.model: pin.Model = pin.buildModelFromXML(urdf_xml, mimic=True)
            except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
                failure = exc
        if errors:  # urdfdom's own words; an element it could not read is dropped, not a model to use
            raise InputError(f"Pinocchio cannot load this URDF (urdfdom: {errors[0]})", file=source)
        if failure is not None:
            raise InputError(f"Pinocchio cannot load this URDF ({failure})", file=source)
        try:
            self._coordinates = Coordinates(self.model)
        except UnsupportedJoint as exc:  # unreachable from a URDF today; kept so a new Pinocchio type cannot crash
            raise InputError(f"unsupported joint {exc}", file=source) from None
        #: Names of the configuration columns (joint names; ``<joint>.x`` etc. for planar and floating joints).
        self.joint_names: tuple[str, ...] = self._coordinates.names
        #: ``(nq,)`` limits of each coordinate (``±inf`` for continuous, planar and floating joints).
        self.lower: FloatArray = self._coordinates.lower
        self.upper: FloatArray = self._coordinates.upper
        self.velocity_limit: FloatArray = self._coordinates.velocity
        #: ``(nq,)`` bool: the coordinate is a length (metres), not an angle (radians).
        self.in_metres: np.ndarray = self._coordinates.in_metres
        self._data = self.model.createData()
        try:
            self._batch: BatchForwardKinematics | None = BatchForwardKinematics(self.model)
        except NotImplementedError:  # a joint the fast path does not compile: Pinocchio evaluates it
            self._batch = None

    # --- construction -------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike[str] | None = None) -> Robot:
        """Load a URDF file; ``None`` loads the bundled SDA10F with its nominal tool frames.

        The robot carries the SDA10F's rig (:func:`sda10f_rig`): ``--urdf`` names an SDA10F URDF
        (a calibrated one). A URDF of another robot loads, but its :attr:`rig` refuses: describe it
        (:func:`brachycal.model.description.load_description`).
        """
        file = Path(path) if path is not None else bundled_urdf_path()
        try:
            text = read_input_text(file, max_bytes=MAX_DOCUMENT_BYTES)
        except UnicodeDecodeError as exc:
            raise InputError(f"not a UTF-8 URDF ({exc})", file=file) from None
        robot = cls(text, base_dir=file.parent, source=str(file))
        robot._sda10f_rig_on_demand = True
        return robot

    @property
    def rig(self) -> Rig:
        """Which arm holds which tool, the ready stance, collision pairs, controller order, workspace:
        what the dual-arm calibration needs.

        Raises:
            InputError: the robot has none, in one line saying that a needle arm and a probe arm are
                needed: a description of ``[[arm]]`` tables (a single arm), a model built from URDF
                text without a description, or one loaded by :meth:`load` that is not the SDA10F
                (its joints are not the SDA10F's).
        """
        if self._rig is None and self._sda10f_rig_on_demand:
            rig = sda10f_rig()
            if rig.joint_names != self.joint_names or not all(
                self.model.existFrame(f) for f in (rig.needle_flange, rig.probe_flange, *rig.tool_frame_parents)
            ):
                raise InputError(
                    "this URDF is not the SDA10F's (its joints or tool frames differ), and this needs a needle arm "
                    "and a probe arm: give a dual-arm robot description (--robot FILE, docs/robots.md)",
                    file=self.source,
                )
            self._rig = rig
        if self._rig is None and self._arms is not None:
            names = ", ".join(arm.name for arm in self._arms)
            raise InputError(
                f"robot {self._described_as!r} names no needle arm and probe arm (its arms: {names}): this needs a "
                "dual-arm robot, a description with [needle_arm] and [probe_arm] (docs/robots.md)",
                file=self.source,
            )
        if self._rig is None:
            raise InputError(
                "this robot model has no description of its arms and tools, and this needs a needle arm and a probe "
                "arm: give a dual-arm robot description (--robot FILE, docs/robots.md)",
                file=self.source,
            )
        return self._rig

    @property
    def has_rig(self) -> bool:
        """Whether :attr:`rig` is there (a dual-arm description, or the SDA10F loaded by :meth:`load`)."""
        try:
            _ = self.rig
        except InputError:
            return False
        return True

    @property
    def arms(self) -> tuple[Arm, ...]:
        """The robot's arms (:class:`~brachycal.model.rig.Arm`): a description's ``[[arm]]`` tables, a
        dual-arm rig's needle arm and probe arm, none for a plain URDF that is not the SDA10F's."""
        if self._arms is not None:
            return self._arms
        return self.rig.arms if self.has_rig else ()

    def arm(self, name: str | None = None) -> Arm:
        """The arm called ``name``; ``None``: the robot's only arm.

        Raises:
            InputError: no such arm, or ``None`` and the robot has not exactly one arm.
        """
        arms = self.arms
        if name is None:
            if len(arms) != 1:
                what = f"{len(arms)} arms ({', '.join(a.name for a in arms)})" if arms else "no arm named"
                raise InputError(f"this robot has {what}: name the arm (docs/robots.md, 'Any arm')", file=self.source)
            return arms[0]
        for arm in arms:
            if arm.name == name:
                return arm
        known = ", ".join(a.name for a in arms) or "none"
        raise InputError(f"no arm {name!r} (arms: {known})", file=self.source)

    def with_arms(self, arms: tuple[Arm, ...], name: str) -> Robot:
        """The same model carrying the ``arms`` of the description ``name`` (one without a rig).

        Raises:
            InputError: an arm names a frame or a joint this robot does not have.
        """
        for arm in arms:
            for frame in (arm.base, arm.flange, *([arm.tool] if arm.tool else [])):
                self.frame_id(frame)
            unknown = [j for j in arm.joints if j not in self.joint_names]
            if unknown:
                raise InputError(f"arm {arm.name!r}: unknown joint {unknown[0]!r}", file=self.source)
        out = copy.copy(self)
        out._data = self.model.createData()
        out._rig, out._sda10f_rig_on_demand = None, False
        out._arms, out._described_as = tuple(arms), name
        return out

    def with_rig(self, rig: Rig) -> Robot:
        """The same model carrying ``rig`` (its joint names must be the robot's).

        Raises:
            InputError: the rig's joints are not this robot's coordinates.
        """
        if rig.joint_names != self.joint_names:
            raise InputError(f"the rig {rig.name!r} names other joints than this robot's", file=self.source)
        out = copy.copy(self)  # the model is shared (never modified); its scratch data is not
        out._data = self.model.createData()
        out._rig, out._sda10f_rig_on_demand = rig, False
        out._arms, out._described_as = None, None
        return out

    @property
    def urdf_xml(self) -> str:
        """The URDF text (with every joint origin this robot moved)."""
        if self._text is None:
            root = urdf_text.parse(self._read_text, self.source)
            for name, T in self._moved.items():
                urdf_text.set_joint_origin(root, name, T, self.source)
            self._text = urdf_text.to_text(root)
            self._tree = urdf_text.parse(self._text, self.source)
        return self._text

    @property
    def _root(self) -> ET.Element:
        """The parsed :attr:`urdf_xml`."""
        if self._tree is None:
            _ = self.urdf_xml
        assert self._tree is not None  # set by urdf_xml
        return self._tree

    def _like_this(self, urdf_xml: str) -> Robot:
        """A robot of new URDF text with this one's folder, name and rig."""
        out = Robot(urdf_xml, base_dir=self.base_dir, source=self.source, rig=self._rig)
        out._sda10f_rig_on_demand = self._sda10f_rig_on_demand
        out._arms, out._described_as = self._arms, self._described_as
        return out

    # --- names and configurations -------------------------------------------------------
    @property
    def nq(self) -> int:
        """Number of configuration coordinates (Pinocchio's ``model.nq`` may differ; see the module docstring)."""
        return len(self.joint_names)

    @property
    def fk_backend(self) -> str:
        """``"batch"`` (vectorised NumPy path) or ``"pinocchio"`` (one Pinocchio call per configuration)."""
        return "batch" if self._batch is not None else "pinocchio"

    @property
    def joint_kinds(self) -> dict[str, str]:
        """Each moving URDF joint's kind: ``revolute``, ``prismatic``, ``continuous``, ``planar``,
        ``floating`` or ``mimic`` (:mod:`brachycal.model.joints`), by joint name, in model order."""
        return {joint.name: joint.kind for joint in self._coordinates.joints}

    def to_pinocchio(self, Q: ArrayLike) -> FloatArray:
        """``(N, model.nq)`` Pinocchio configurations of ``(N, nq)`` configurations (the same array if equal)."""
        Q = np.asarray(Q, dtype=float)
        self._check_shape(Q)
        return self._coordinates.to_pinocchio(Q)

    @property
    def frame_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.model.frames)

    def frame_id(self, frame: str) -> int:
        """Pinocchio index of a frame; :class:`InputError` listing the tool frames if unknown."""
        if not self.model.existFrame(frame):
            raise InputError(f"unknown frame {frame!r}; links include {', '.join(self._links())}")
        return int(self.model.getFrameId(frame))

    def _links(self) -> list[str]:
        return [f.name for f in self.model.frames if f.type == pin.FrameType.BODY]

    def configuration(self, named: Mapping[str, float]) -> FloatArray:
        """``(nq,)`` configuration from ``{joint name: radians}``; every joint must be given."""
        missing = [n for n in self.joint_names if n not in named]
        if missing:
            raise InputError(f"missing joint(s): {', '.join(missing)}")
        return np.array([float(named[n]) for n in self.joint_names])

    def named(self, q: ArrayLike) -> dict[str, float]:
        """``{joint name: radians}`` of one ``(nq,)`` configuration."""
        q = np.asarray(q, dtype=float).reshape(self.nq)
        return dict(zip(self.joint_names, q.tolist(), strict=True))

    def neutral(self) -> FloatArray:
        """``(nq,)`` all-zero configuration (the vendor's home pose; Pinocchio's neutral configuration)."""
        return np.zeros(self.nq)

    def within_limits(self, q: ArrayLike, margin: float = 0.0) -> np.bool_ | NDArray[np.bool_]:
        """Whether each configuration of ``(nq,)`` or ``(N, nq)`` is inside the limits by ``margin`` rad
        (a NumPy bool for one configuration, ``(N,)`` bools for N)."""
        q = np.asarray(q, dtype=float)
        inside = (q >= self.lower + margin) & (q <= self.upper - margin)
        return inside.all(axis=-1)

    # --- kinematics ---------------------------------------------------------------------
    def fk(self, frame: str, q: ArrayLike) -> FloatArray:
        """``T_base_frame``: ``(4, 4)`` for ``q`` of shape ``(nq,)``, ``(N, 4, 4)`` for ``(N, nq)``.

        Same back end for one configuration as for many (:attr:`fk_backend`).
        """
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            return self.fk_frames([frame], q[None])[0, 0]
        return self.fk_frames([frame], q)[0]

    def fk_frames(
        self,
        frames: Sequence[str],
        Q: ArrayLike,
        progress: Callable[[int], None] | None = None,
    ) -> FloatArray:
        """``(F, N, 4, 4)`` poses ``T_base_frame`` of several frames for ``(N, nq)`` configurations.

        Evaluated by :attr:`fk_backend` (vectorised over configurations on the batch path, see
        :mod:`brachycal.model.batch_fk`) in blocks of :data:`CHUNK`; ``progress(n)`` is called with
        the number of configurations done after each block.
        """
        Q = np.asarray(Q, dtype=float)
        self._check_shape(Q)
        ids = [self.frame_id(f) for f in frames]
        evaluate = self._batch.frame_poses if self._batch is not None else self._pinocchio_frame_poses
        out = np.empty((len(ids), Q.shape[0], 4, 4))
        for start in range(0, Q.shape[0], CHUNK):
            block = Q[start : start + CHUNK]
            out[:, start : start + len(block)] = evaluate(ids, self._coordinates.to_pinocchio(block))
            if progress is not None:
                progress(len(block))
        return out

    def fk_frames_loop(self, frames: Sequence[str], Q: ArrayLike) -> FloatArray:
        """Same as :meth:`fk_frames`, one Pinocchio call per configuration (the reference path)."""
        Q = np.asarray(Q, dtype=float)
        self._check_shape(Q)
        return self._pinocchio_frame_poses([self.frame_id(f) for f in frames], self._coordinates.to_pinocchio(Q))

    def _pinocchio_frame_poses(self, frame_ids: list[int], Q_pin: FloatArray) -> FloatArray:
        """``(F, N, 4, 4)`` frame poses for ``(N, model.nq)`` Pinocchio configurations, one call each."""
        out = np.empty((len(frame_ids), Q_pin.shape[0], 4, 4))
        model, data = self.model, self._data
        for i, q in enumerate(Q_pin):
            pin.forwardKinematics(model, data, q)
            for k, fid in enumerate(frame_ids):
                out[k, i] = pin.updateFramePlacement(model, data, fid).homogeneous
        return out

    def transform(self, frame_a: str, frame_b: str, q: ArrayLike) -> FloatArray:
        """``T_a_b`` (pose of ``frame_b`` in ``frame_a``), ``(4, 4)`` or ``(N, 4, 4)`` like :meth:`fk`."""
        q = np.asarray(q, dtype=float)
        poses = self.fk_frames([frame_a, frame_b], np.atleast_2d(q))
        T_a_b = inverse(poses[0]) @ poses[1]
        return T_a_b[0] if q.ndim == 1 else T_a_b

    def _check_shape(self, Q: FloatArray) -> None:
        if Q.ndim != 2 or Q.shape[1] != self.nq:
            raise ValueError(f"configurations must have shape (N, {self.nq}), got {Q.shape}")

    # --- tool frames --------------------------------------------------------------------
    def tool_transform(self, frame: str) -> tuple[str, FloatArray]:
        """``(parent link, T_parent_frame (4, 4))`` of a frame attached by a fixed joint."""
        return urdf_text.fixed_joint_transform(self._root, frame, self.source)

    def with_tool_transform(self, frame: str, T_parent_frame: ArrayLike) -> Robot:
        """A new robot (the same rig) whose fixed joint ending at ``frame`` has origin ``T_parent_frame``."""
        root = urdf_text.parse(self.urdf_xml, self.source)
        urdf_text.set_fixed_joint_transform(root, frame, np.asarray(T_parent_frame, dtype=float), self.source)
        return self._like_this(urdf_text.to_text(root))

    def with_joint_origins(self, origins: Mapping[str, ArrayLike]) -> Robot:
        """A new robot (the same rig) whose joints ``name`` have ``<origin>`` ``T_parent_joint`` ``(4, 4)``.

        Used to build a "physical" robot whose geometry differs slightly from the nominal one, and by
        robot identification at every evaluation. When every joint named is a revolute, continuous or
        prismatic one, the Pinocchio model is copied and moved directly (a joint's placement in its
        parent joint is the fixed joints' chain to its parent link, then its origin: the new placement
        is the old one times ``T_old⁻¹ T_new``) and the text is written on first use (:attr:`urdf_xml`);
        otherwise (a fixed joint's origin moves its subtree of frames) the text is re-read.
        """
        moved = {name: np.asarray(T, dtype=float) for name, T in origins.items()}
        one_axis = {joint.name for joint in self._coordinates.joints if joint.kind in ONE_AXIS}
        if moved and all(name in one_axis and T.shape == (4, 4) for name, T in moved.items()):
            return self._moved_directly(moved)
        root = urdf_text.parse(self.urdf_xml, self.source)
        for name, T in origins.items():
            urdf_text.set_joint_origin(root, name, np.asarray(T, dtype=float), self.source)
        return self._like_this(urdf_text.to_text(root))

    def joint_axis(self, name: str) -> FloatArray:
        """``(3,)`` unit axis of a one-axis joint in its own frame (rotation axis, or slide direction).

        Raises:
            InputError: no such joint, or a joint without one axis (planar, floating, mimic).
        """
        try:
            joint = self._coordinates.joint(name)
        except KeyError:
            raise InputError(f"unknown joint {name!r}", file=self.source) from None
        if joint.kind not in ONE_AXIS or joint.axis is None:
            raise InputError(f"joint {name!r} is {joint.kind}: it has no single axis", file=self.source)
        return joint.axis.copy()

    def with_joint_offsets(self, offsets_rad: Mapping[str, float]) -> Robot:
        """A robot (the same rig) whose revolute joints read ``q`` where this one reads ``q + offset``.

        ``FK_new(q) = FK_this(q + offsets)``: each offset turns the joint's origin about its axis.
        """
        from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

        origins = {}
        for name, offset in offsets_rad.items():
            turn = Rotation.from_rotvec(float(offset) * self.joint_axis(name)).as_matrix()
            origins[name] = self.joint_origin(name) @ make_transform(turn, np.zeros(3))
        return self.with_joint_origins(origins)

    def _moved_directly(self, moved: Mapping[str, FloatArray]) -> Robot:
        """:meth:`with_joint_origins` of one-axis joints, on a copy of the Pinocchio model (no URDF re-read)."""
        model = pin.Model(self.model)
        for name, T in moved.items():
            jid = model.getJointId(name)
            change = inverse(self.joint_origin(name)) @ T
            model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(change[:3, :3], change[:3, 3])
        out = copy.copy(self)  # the coordinates (names, limits, axes) do not depend on the placements
        out.model = model
        out._data = model.createData()
        out._batch = BatchForwardKinematics(model) if self._batch is not None else None
        out._moved = {**self._moved, **{name: T.copy() for name, T in moved.items()}}
        out._text, out._tree = None, None  # written on first use; the origins read so far stay good
        return out

    def joint_origin(self, name: str) -> FloatArray:
        """``T_parent_joint (4, 4)``: the ``<origin>`` of joint ``name`` in the URDF."""
        if name in self._moved:
            return self._moved[name].copy()
        if name not in self._read_origins:  # read once: identification asks at every evaluation
            self._read_origins[name] = urdf_text.joint_origin(self._root, name, self.source)
        return self._read_origins[name].copy()

    def write_urdf(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """Write the URDF (with the current tool joints) atomically; mesh paths stay valid.

        Relative mesh paths are rewritten relative to the new file's folder, so the written file
        loads in Pinocchio, MuJoCo, yourdfpy and ROS tools from wherever it is written.
        """
        path = Path(path)
        root = urdf_text.parse(self.urdf_xml, self.source)
        urdf_text.rebase_mesh_paths(root, self.base_dir, path.parent)
        with atomic_open(path, force=force) as handle:
            handle.write(urdf_text.to_text(root))
        return path

    def bundled_urdf(
        self, mesh_prefix: str = "meshes", record: Mapping[str, str] | None = None
    ) -> tuple[str, dict[str, Path]]:
        """``(URDF text, {mesh copy below mesh_prefix: source file})`` for a self-contained folder.

        Every mesh path of the text points below ``mesh_prefix`` (``"meshes"``: a ``meshes/`` folder
        next to the URDF; ``"package://NAME/meshes"``: a ROS package), and the returned files are
        the copies to make there (only the meshes this URDF names): the folder then loads wherever
        it is copied. ``record`` (attributes of a ``<brachycal_export>`` element: which result the
        text was written from and which corrections it carries) is added to the text.

        Raises:
            InputError: a mesh of the URDF is not a readable file.
        """
        root = urdf_text.parse(self.urdf_xml, self.source)
        copies = urdf_text.bundle_meshes(root, self.base_dir, mesh_prefix, self.source)
        if record is not None:
            urdf_text.set_export_record(root, dict(record))
        return urdf_text.to_text(root), copies

    @property
    def export_records(self) -> list[dict[str, str]]:
        """The ``<brachycal_export>`` records of this URDF (:meth:`bundled_urdf`; empty: none)."""
        return urdf_text.export_records(self._root)

    # --- other libraries' views of the same file ------------------------------------------
    def collision_model(self) -> pin.GeometryModel:
        """Pinocchio collision geometry (the URDF's ``<collision>`` meshes)."""
        return pin.buildGeomFromUrdfString(
            self.model, self.urdf_xml, pin.GeometryType.COLLISION, package_dirs=[str(self.base_dir)]
        )

    def mujoco_model(self) -> mujoco.MjModel:  # (MuJoCo imported lazily: it is only for planning)
        """MuJoCo model of the same URDF's collision geometry; fixed links stay bodies, so tool frames
        are addressable.

        MuJoCo reads only its own mesh formats (STL, OBJ, MSH): other collision meshes (Baxter's
        COLLADA ``.DAE``) are converted to STL in memory (trimesh), and every mesh is handed over
        under a name of its own (``m<k>_<stem>.<ext>``: MuJoCo strips folders, so two files of the same
        name in different folders would clash). Visual geometry is dropped: planning never sees it.
        """
        import mujoco  # lazy: start-up (mujoco)

        root = urdf_text.parse(self.urdf_xml, self.source)
        for link in root.iter("link"):
            for visual in link.findall("visual"):
                link.remove(visual)
        assets: dict[str, bytes] = {}
        asset_names: dict[Path, str] = {}
        for mesh in root.iter("mesh"):
            path = (self.base_dir / mesh.get("filename", "")).resolve()
            if path not in asset_names:
                name, data = _mujoco_mesh(path, len(asset_names), self.source)
                asset_names[path] = name
                assets[name] = data
            mesh.set("filename", asset_names[path])
        return mujoco.MjModel.from_xml_string(urdf_text.to_text(root), assets=assets)


#: Mesh formats MuJoCo decodes itself.
_MUJOCO_MESH_SUFFIXES = (".stl", ".obj", ".msh")


_STDERR_LOCK = threading.Lock()
#: Most of urdfdom's messages kept from one parse (bytes): a few lines per error.
_MAX_URDFDOM_BYTES = 1 << 16


@contextlib.contextmanager
def urdfdom_errors() -> Iterator[list[str]]:
    """The errors urdfdom (Pinocchio's URDF parser, C++) reports while the block runs, filled in
    when it ends: ``["Joint [j] is of type REVOLUTE but it does not specify limits", ...]``.

    urdfdom prints them (``Error:   ...`` and an ``at line N in file.cpp`` line) on the process's
    standard error, ahead of the refusal that names the file; the block's standard error (file
    descriptor 2) goes to a pipe instead (no file written: a full disk cannot stop a robot from
    loading), and is restored when the block ends. Any other text written there meanwhile
    (another thread's) is written back; past the pipe's buffer (64 KiB) text is dropped, never waited on.
    """
    errors: list[str] = []
    with _STDERR_LOCK:
        with contextlib.suppress(ValueError, OSError):  # a closed or replaced sys.stderr: nothing to flush
            sys.stderr.flush()
        read_end, write_end = os.pipe()
        os.set_blocking(write_end, False)
        saved = os.dup(2)
        try:
            try:
                os.dup2(write_end, 2)
            finally:
                os.close(write_end)
            yield errors
        finally:
            os.dup2(saved, 2)  # the pipe's last writer gone: reading it ends
            os.close(saved)
            with os.fdopen(read_end, "rb") as pipe:
                said = pipe.read(_MAX_URDFDOM_BYTES)
            others: list[str] = []
            for line in said.decode("utf-8", "replace").splitlines(keepends=True):
                if line.startswith("Error:"):
                    errors.append(line.removeprefix("Error:").strip())
                elif not line.startswith(("Warning:", "Info:", "Debug:", "         at line ")):
                    others.append(line)
            if others:
                os.write(2, "".join(others).encode())


def _mujoco_mesh(path: Path, k: int, source: str) -> tuple[str, bytes]:
    """``(asset name, bytes)`` of a collision mesh for MuJoCo: as it is, or converted to STL.

    Raises:
        InputError: the mesh cannot be read or converted.
    """
    suffix = path.suffix.lower()
    try:
        if suffix in _MUJOCO_MESH_SUFFIXES:
            return f"m{k}_{path.stem}{suffix}", read_input_bytes(path, max_bytes=MAX_MESH_BYTES)
        return f"m{k}_{path.stem}.stl", _stl_bytes(path, check_input_file(path, max_bytes=MAX_MESH_BYTES).st_mtime_ns)
    except InputError as exc:
        raise InputError(f"cannot read collision mesh {path} ({exc.problem})", file=source) from None
    except OSError as exc:
        raise InputError(f"cannot read collision mesh {path} ({exc.strerror})", file=source) from None
    except Exception as exc:  # trimesh and pycollada refuse an undecodable file with assorted types
        raise InputError(f"cannot convert collision mesh {path} to STL for MuJoCo ({exc})", file=source) from None


@functools.lru_cache(maxsize=64)
def _stl_bytes(path: Path, mtime_ns: int) -> bytes:
    """Binary STL of a mesh file trimesh reads (COLLADA through pycollada), cached by file and
    modification time: converting Baxter's torso takes 0.07 s and every planner asks again."""
    import trimesh  # lazy: start-up (trimesh)

    mesh = trimesh.load(path, force="mesh")
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError("no triangles in it")
    buffer = io.BytesIO()
    mesh.export(buffer, file_type="stl")
    return buffer.getvalue()
