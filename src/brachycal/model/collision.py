"""Which link pairs can collide, and how far apart they are (Pinocchio + Coal).

The pairs are every two links with collision geometry, minus parent–child links and minus the
pairs the vendor's MoveIt configuration (``urdf/motoman_sda10f.srdf``, computed by sampling) marks
as never colliding. Distances use the convex hulls of the collision meshes, as MuJoCo does, so
the planner (MuJoCo) and the verifier (Coal) judge the same shapes with independent code.
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
from brachycal.files import bundled
from brachycal.model.robot import Robot


def srdf_disabled_pairs(path: Path | None = None) -> set[frozenset[str]]:
    """Link pairs a MoveIt SRDF disables (``<disable_collisions>``); the bundled SDA10F's by default.

    Raises:
        InputError: naming the file, when a ``<disable_collisions>`` lacks ``link1`` or ``link2``.
    """
    source = path or bundled("urdf", "motoman_sda10f.srdf")
    pairs: set[frozenset[str]] = set()
    for element in ET.parse(source).getroot().iter("disable_collisions"):
        link1, link2 = element.get("link1"), element.get("link2")
        if not link1 or not link2:
            raise InputError("a <disable_collisions> needs both link1 and link2", file=source)
        pairs.add(frozenset((link1, link2)))
    return pairs


def _link_of(robot: Robot, geometry: pin.GeometryObject) -> str:
    return robot.model.frames[geometry.parentFrame].name


def collision_link_pairs(robot: Robot, disabled: set[frozenset[str]] | None = None) -> list[tuple[str, str]]:
    """Link pairs to keep apart, sorted: links with geometry, not parent–child, not disabled."""
    disabled = srdf_disabled_pairs() if disabled is None else disabled
    geometry = robot.collision_model()
    links = sorted({_link_of(robot, obj) for obj in geometry.geometryObjects})
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
        for obj in geometry.geometryObjects:
            obj.geometry.buildConvexHull(True, "Qt")
            obj.geometry = obj.geometry.convex
        index = {_link_of(self.robot, obj): k for k, obj in enumerate(geometry.geometryObjects)}
        for a, b in self.pairs:
            geometry.addCollisionPair(pin.CollisionPair(index[a], index[b]))
        self._geometry = geometry
        self._geometry_data = pin.GeometryData(geometry)
        self._data = self.robot.model.createData()

    def distances(self, q: ArrayLike) -> np.ndarray:
        """``(P,)`` distances in metres of :attr:`pairs` at configuration ``q`` (negative: overlap)."""
        pin.computeDistances(self.robot.model, self._data, self._geometry, self._geometry_data, np.asarray(q, float))
        return np.array([r.min_distance for r in self._geometry_data.distanceResults])
