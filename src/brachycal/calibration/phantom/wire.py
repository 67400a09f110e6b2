"""Arbitrary-wire phantom calibration (Shen et al., the paper's ref. [27]): each image point lies on its wire.

Design: ``docs/design/phantoms.md``, "Arbitrary-wire phantom".
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brachycal.calibration.phantom.features import FeatureRows, PhantomResult, check_layout, fit_phantom
from brachycal.calibration.phantom.phantom_file import (
    MM,
    PhantomGeometry,
    PhantomObservations,
    entries,
    load_toml,
    read_observations,
    unique_name,
    vector,
)
from brachycal.data.formats.plus_files import Wire
from brachycal.errors import DegenerateDataError, InputError
from brachycal.io import bundled
from brachycal.se3 import FloatArray

KIND = "wire"
#: The bundled default geometry (six wires in six directions through a 60 mm box).
DEFAULT_GEOMETRY = ("phantoms", "arbitrary_wire.toml")
#: Fewest wires: each point gives two equations, the image plane's pose has six degrees of freedom.
MIN_WIRES = 3


def perpendiculars(direction: FloatArray) -> FloatArray:
    """``(2, 3)`` orthonormal directions perpendicular to the unit ``direction (3,)``."""
    helper = np.eye(3)[int(np.argmin(np.abs(direction)))]
    e1 = np.cross(direction, helper)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(direction, e1)])


@dataclass(frozen=True)
class WirePhantom:
    """An arbitrary-wire phantom: its wires (metres, phantom frame) and the shared geometry."""

    wires: tuple[Wire, ...]
    geometry: PhantomGeometry

    @property
    def names(self) -> list[str]:
        return [w.name for w in self.wires]

    def wire(self, name: str) -> Wire:
        return self.wires[self.names.index(name)]

    def nominal_rows(self) -> FeatureRows:
        """One nominal image's equations: the plane ``y = middle`` crossing every wire (layout check)."""
        centre_y = float(np.mean([(w.front_m[1] + w.back_m[1]) / 2 for w in self.wires]))
        R = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # image axes (x, −z, y) of the phantom
        uv, g, d = [], [], []
        for wire in self.wires:
            a, b = wire.front_m, wire.back_m
            if abs(b[1] - a[1]) < 1e-9:
                raise DegenerateDataError(
                    f"{self.geometry.source}: wire {wire.name!r} runs across the scan direction y (in the image "
                    "plane): it shows as a line, not a point"
                )
            p = a + (centre_y - a[1]) / (b[1] - a[1]) * (b - a)
            uv.append([p[0], -p[2]])
            e = perpendiculars((b - a) / np.linalg.norm(b - a))
            g.extend(e @ R)
            d.extend(e @ (a - np.array([0.0, centre_y, 0.0])))
        k = np.repeat(np.arange(len(uv)), 2)
        return FeatureRows(np.zeros(len(k), dtype=int), np.repeat(np.array(uv), 2, axis=0), np.array(g), np.array(d), k)


def read_wire_phantom(path: str | os.PathLike[str] | None = None) -> WirePhantom:
    """Read an arbitrary-wire geometry (:mod:`brachycal.calibration.phantom.phantom_file`); default: the bundled one.

    Raises:
        InputError: a malformed file, a wire of zero length, a repeated name.
        DegenerateDataError: an ill-posed layout (module docstring).
    """
    path = bundled(*DEFAULT_GEOMETRY) if path is None else path
    data, geometry = load_toml(path, KIND)
    where = None if geometry.source is None else Path(geometry.source)
    wires: list[Wire] = []
    seen: set[str] = set()
    for table in entries(data, "wire", where):
        name = unique_name(table, "wire", seen, where)
        a = vector(table.get("from_mm"), f"wire {name!r} from_mm", where) * MM
        b = vector(table.get("to_mm"), f"wire {name!r} to_mm", where) * MM
        if not np.linalg.norm(b - a) > 0:
            raise InputError(f"wire {name!r} has zero length (from_mm = to_mm)", file=where)
        wires.append(Wire(name, a, b))
    if len(wires) < MIN_WIRES:
        raise DegenerateDataError(
            f"{geometry.source}: {len(wires)} wire(s): at least {MIN_WIRES} are needed (two equations per wire, "
            "six for the image plane's pose)"
        )
    directions = np.array([(w.back_m - w.front_m) / np.linalg.norm(w.back_m - w.front_m) for w in wires])
    if np.linalg.matrix_rank(directions, tol=1e-6) < 2:
        raise DegenerateDataError(
            f"{geometry.source}: all {len(wires)} wires are parallel: the image plane's position along them is "
            "free (every image looks the same as the probe slides along the wires)"
        )
    phantom = WirePhantom(tuple(wires), geometry)
    check_layout(phantom.nominal_rows(), "the wires", geometry.source)
    return phantom


def wire_rows(phantom: WirePhantom, observations: PhantomObservations) -> tuple[FeatureRows, FloatArray]:
    """The fit's equations (two per point) and ``T_phantom_marker (F, 4, 4)``."""
    g, d = [], []
    for name in observations.feature:
        wire = phantom.wire(name)
        e = perpendiculars((wire.back_m - wire.front_m) / np.linalg.norm(wire.back_m - wire.front_m))
        g.append(e)
        d.append(e @ wire.front_m)
    k = np.arange(len(observations.feature))
    rows = FeatureRows(
        np.repeat(observations.frame, 2),
        np.repeat(observations.uv_px.reshape(-1, 2), 2, axis=0),
        np.array(g).reshape(-1, 3),
        np.array(d).reshape(-1),
        np.repeat(k, 2),
    )
    return rows, observations.T_phantom_marker(phantom.geometry.registration())


def calibrate_wire(phantom: WirePhantom, observations: PhantomObservations) -> PhantomResult:
    """``T_marker_image`` with pixel spacings from a tracked arbitrary-wire session (module docstring).

    Raises:
        DegenerateDataError: too few frames, or data that cannot determine the fit.
        SolverError: the refinement does not converge.
    """
    rows, T_phantom_marker = wire_rows(phantom, observations)
    return fit_phantom("wire", rows, T_phantom_marker)


def calibrate_wire_files(
    geometry: str | os.PathLike[str], observations: str | os.PathLike[str]
) -> tuple[PhantomResult, WirePhantom, PhantomObservations]:
    """Read a geometry and an observations file and calibrate (the ``brachycal phantom wire`` job)."""
    phantom = read_wire_phantom(geometry)
    seen = read_observations(observations, KIND, phantom.names)
    return calibrate_wire(phantom, seen), phantom, seen
