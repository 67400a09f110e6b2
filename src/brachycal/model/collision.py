"""Which link pairs can collide, and how far apart they are (Pinocchio + Coal).

The pairs are every two links with collision geometry, minus parent–child links and minus the
pairs the robot's MoveIt configuration marks as never colliding (``robot.rig.disabled_pairs``, read
from the description's SRDFs; the SDA10F's is ``urdf/motoman_sda10f.srdf``, computed by sampling).
Distances use the convex hulls of the collision meshes, as MuJoCo does, so the planner (MuJoCo)
and the verifier (Coal) judge the same shapes with independent code.
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_bytes
from brachycal.io import bundled
from brachycal.model.robot import Robot


def srdf_disabled_pairs(path: Path | None = None) -> set[frozenset[str]]:
    """Link pairs a MoveIt SRDF disables (``<disable_collisions>``); the bundled SDA10F's by default.

    Raises:
        InputError: naming the file, when a ``<disable_collisions>`` lacks ``link1`` or ``link2``.
    """
    source = path or bundled("urdf", "motoman_sda10f.srdf")
    pairs: set[frozenset[str]] = set()
    for element in ET.fromstring(read_input_bytes(source, max_bytes=MAX_DOCUMENT_BYTES)).iter("disable_collisions"):
        link1, link2 = element.get("link1"), element.get("link2")
        if not link1 or not link2:
            raise InputError("a <disable_collisions> needs both link1 and link2", file=source)
        pairs.add(frozenset((link1, link2)))
    return pairs


def _link_of(robot: Robot, geometry: pin.GeometryObject) -> str:
    return robot.model.frames[geometry.parentFrame].name


def collision_link_pairs(robot: Robot, disabled: set[frozenset[str]] | None = None) -> list[tuple[str, str]]:
    """Link pairs to keep apart, sorted: links with geometry, not parent–child, not disabled.

    ``disabled`` defaults to the robot's rig's (``robot.rig.disabled_pairs``, its SRDFs'). The links
    with geometry are read from the URDF's ``<collision>`` elements (the links Pinocchio and MuJoCo
    give collision geometry), without loading the meshes: a plan asks twice (its IK and its check),
    and loading the SDA10F's meshes takes ~0.1 s.

    Raises:
        InputError: ``disabled`` not given and the robot has no rig.
    """
    disabled = set(robot.rig.disabled_pairs) if disabled is None else disabled
    root = ET.fromstring(robot.urdf_xml)
    links = sorted({str(link.get("name")) for link in root.iter("link") if link.find("collision") is not None})
    parent_link = {}
    for link in links:
        frame = robot.model.frames[robot.frame_id(link)]
        joint = robot.model.frames[frame.parentFrame]  # the joint frame this link hangs on
        parent_link[link] = robot.model.frames[joint.parentFrame].name
    pairs = []
    for a, b in itertools.combinations(links, 2):
        if frozenset((a, b)) in disabled or parent_link.get(a) == b or parent_link.get(b) == a:
            continue
        pairs.append((a, b))
    return pairs


@dataclass
class ClearanceChecker:
    """Distances between the convex hulls of link pairs, by Coal through Pinocchio."""

    robot: Robot
    pairs: list[tuple[str, str]]

    def __post_init__(self) -> None:
        geometry = self.robot.collision_model()
        objects: dict[str, list[int]] = {}
        for k, obj in enumerate(geometry.geometryObjects):
            if hasattr(obj.geometry, "buildConvexHull"):  # a mesh; spheres, boxes and cylinders are convex already
                obj.geometry.buildConvexHull(True, "Qt")
                obj.geometry = obj.geometry.convex
            objects.setdefault(_link_of(self.robot, obj), []).append(k)
        # A link may carry several collision shapes (Baxter's head: two spheres): a link pair's
        # distance is the smallest over its shapes' pairs.
        self._owner: list[int] = []
        for p, (a, b) in enumerate(self.pairs):
            for i in objects[a]:
                for j in objects[b]:
                    geometry.addCollisionPair(pin.CollisionPair(i, j))
                    self._owner.append(p)
        self._geometry = geometry
        self._geometry_data = pin.GeometryData(geometry)
        self._data = self.robot.model.createData()

    def distances(self, q: ArrayLike) -> np.ndarray:
        """``(P,)`` distances in metres of :attr:`pairs` at configuration ``q`` ``(nq,)`` (negative: overlap)."""
        # brachycal's coordinates, not Pinocchio's: they differ for continuous, planar and floating joints.
        q_pin = self.robot.to_pinocchio(np.asarray(q, dtype=float)[None])[0]
        pin.computeDistances(self.robot.model, self._data, self._geometry, self._geometry_data, q_pin)
        shapes = np.array([r.min_distance for r in self._geometry_data.distanceResults])
        out = np.full(len(self.pairs), np.inf)
        np.minimum.at(out, np.asarray(self._owner, dtype=int), shapes)
        return out
