"""The joints of a Pinocchio model as brachycal sees them: kind, axis, configuration coordinates.

The one place that reads joint types and axes out of a Pinocchio model; the batch forward
kinematics (:mod:`brachycal.model.batch_fk`) and :class:`~brachycal.model.robot.Robot` both use it.

A brachycal configuration carries one number per degree of freedom, as joint logs do; Pinocchio's
own configuration vector differs for some joints. Per URDF joint type:

============  ==========================================  =====================================
URDF type     brachycal coordinates                       Pinocchio configuration
============  ==========================================  =====================================
revolute      the angle (rad)                             the same
prismatic     the position (m)                            the same
continuous    the angle (rad), unbounded                  ``(cos, sin)`` of the angle
planar        ``x``, ``y`` (m) and the angle ``theta``    ``(x, y, cos θ, sin θ)``
              (rad) in the joint frame's xy plane
floating      ``x``, ``y``, ``z`` (m) and ``roll``,        ``(x, y, z, qx, qy, qz, qw)``
              ``pitch``, ``yaw`` (rad, URDF convention
              ``R = Rz(yaw) Ry(pitch) Rx(roll)``)
mimic         none: the joint follows its leader           none (Pinocchio computes it)
              (``multiplier × leader + offset``)
============  ==========================================  =====================================

A 1-DoF joint's coordinate is named after the joint; a planar or floating joint's coordinates are
``<joint>.x``, ``<joint>.y``, ... The all-zero configuration is Pinocchio's neutral one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from brachycal.se3 import FloatArray

#: Coordinates of the multi-DoF joints, in order (see the module docstring).
PLANAR_COORDINATES = ("x", "y", "theta")
FLOATING_COORDINATES = ("x", "y", "z", "roll", "pitch", "yaw")
#: Kinds with one axis and one coordinate.
ONE_AXIS = ("revolute", "prismatic", "continuous")


class UnsupportedJoint(NotImplementedError):
    """A joint type brachycal does not know how to give a configuration for."""


@dataclass(frozen=True)
class JointInfo:
    """One joint of a Pinocchio model.

    Attributes:
        name: the joint's name.
        jid: Pinocchio joint index (1 and up).
        kind: ``revolute``, ``prismatic``, ``continuous``, ``planar``, ``floating`` or ``mimic``.
        axis: ``(3,)`` unit axis in the joint's own frame (rotation axis, or slide direction) for
            the one-axis kinds, else ``None``.
        idx_q: first index of the joint in Pinocchio's configuration vector.
        idx_v: first index of the joint in Pinocchio's velocity vector.
        coordinates: names of the joint's brachycal coordinates (empty for a mimic joint).
    """

    name: str
    jid: int
    kind: str
    axis: FloatArray | None
    idx_q: int
    idx_v: int
    coordinates: tuple[str, ...]


def _motion_axes(model: pin.Model, jid: int) -> tuple[FloatArray, FloatArray]:
    """``(linear, angular)`` parts ``(3,)`` of a 1-DoF joint's motion subspace, in its own frame."""
    jmodel = model.joints[jid]
    jdata = jmodel.createData()
    jmodel.calc(jdata, pin.neutral(model))  # the subspace of these joints does not depend on q
    S = np.asarray(jdata.S).reshape(6)
    return S[:3].copy(), S[3:].copy()


def joint_info(model: pin.Model, jid: int) -> JointInfo:
    """Classify joint ``jid`` of ``model``.

    Raises:
        UnsupportedJoint: a joint no URDF produces (spherical, helical, composite, ...).
    """
    jmodel, name = model.joints[jid], str(model.names[jid])
    shortname = jmodel.shortname()
    kind: str
    axis: FloatArray | None = None
    coordinates: tuple[str, ...] = (name,)
    if shortname == "JointModelMimic":
        kind, coordinates = "mimic", ()
    elif shortname == "JointModelFreeFlyer":
        kind, coordinates = "floating", tuple(f"{name}.{c}" for c in FLOATING_COORDINATES)
    elif shortname == "JointModelPlanar":
        kind, coordinates = "planar", tuple(f"{name}.{c}" for c in PLANAR_COORDINATES)
    elif jmodel.nv == 1 and jmodel.nq in (1, 2):
        linear, angular = _motion_axes(model, jid)
        if np.any(angular) and not np.any(linear):
            kind, axis = ("revolute" if jmodel.nq == 1 else "continuous"), angular / np.linalg.norm(angular)
        elif np.any(linear) and not np.any(angular) and jmodel.nq == 1:
            kind, axis = "prismatic", linear / np.linalg.norm(linear)
        else:
            raise UnsupportedJoint(f"{name!r} ({shortname}) is neither a rotation nor a translation")
    else:
        raise UnsupportedJoint(f"{name!r} ({shortname})")
    return JointInfo(name, jid, kind, axis, int(jmodel.idx_q), int(jmodel.idx_v), coordinates)


class Coordinates:
    """brachycal's configuration coordinates of a Pinocchio model (see the module docstring).

    Args:
        model: the Pinocchio model (built with ``mimic=True`` so that mimic joints follow).

    Raises:
        UnsupportedJoint: the model has a joint type no URDF produces.
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.joints: tuple[JointInfo, ...] = tuple(joint_info(model, jid) for jid in range(1, model.njoints))
        self.names: tuple[str, ...] = tuple(c for j in self.joints for c in j.coordinates)
        lower, upper = np.array(model.lowerPositionLimit), np.array(model.upperPositionLimit)
        velocity = np.array(model.velocityLimit)
        self.lower = np.full(len(self.names), -np.inf)
        self.upper = np.full(len(self.names), np.inf)
        self.velocity = np.empty(len(self.names))
        self.in_metres = np.zeros(len(self.names), dtype=bool)
        column = 0
        for j in self.joints:
            n = len(j.coordinates)
            if j.kind in ("revolute", "prismatic"):  # the only kinds with limits on their coordinate
                self.lower[column], self.upper[column] = lower[j.idx_q], upper[j.idx_q]
            # The tangent velocity limits (for a floating joint, the angular ones stand for the rpy rates).
            self.velocity[column : column + n] = velocity[j.idx_v : j.idx_v + n]
            self.in_metres[column : column + n] = {
                "prismatic": [True],
                "planar": [True, True, False],
                "floating": [True, True, True, False, False, False],
            }.get(j.kind, [False] * n)
            column += n
        #: Whether brachycal's coordinates are Pinocchio's configuration as they are: only revolute,
        #: prismatic and mimic joints (no column either way), each at the column Pinocchio gives it.
        moving = [j for j in self.joints if j.kind != "mimic"]
        self.identity = all(j.kind in ("revolute", "prismatic") for j in moving) and [j.idx_q for j in moving] == list(
            range(model.nq)
        )

    def joint(self, name: str) -> JointInfo:
        """The joint called ``name``; :class:`KeyError` if there is none."""
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def to_pinocchio(self, Q: ArrayLike) -> FloatArray:
        """``(N, model.nq)`` Pinocchio configurations of ``(N, len(names))`` coordinates (no copy if identity)."""
        Q = np.asarray(Q, dtype=float)
        if self.identity:
            return Q
        out = np.empty((Q.shape[0], self.model.nq))
        column = 0
        for j in self.joints:
            i = j.idx_q
            if j.kind in ("revolute", "prismatic"):
                out[:, i] = Q[:, column]
            elif j.kind == "continuous":
                out[:, i], out[:, i + 1] = np.cos(Q[:, column]), np.sin(Q[:, column])
            elif j.kind == "planar":
                theta = Q[:, column + 2]
                out[:, i : i + 2] = Q[:, column : column + 2]
                out[:, i + 2], out[:, i + 3] = np.cos(theta), np.sin(theta)
            elif j.kind == "floating":
                from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

                out[:, i : i + 3] = Q[:, column : column + 3]
                # Extrinsic x-y-z angles are URDF's rpy, R = Rz(yaw) Ry(pitch) Rx(roll); scipy's quaternion
                # order (x, y, z, w) is Pinocchio's.
                out[:, i + 3 : i + 7] = Rotation.from_euler("xyz", Q[:, column + 3 : column + 6]).as_quat()
            column += len(j.coordinates)
        return out
