"""Multi-wedge phantom calibration (Najafi et al., Ultrasound Med. Biol. 40(9), 2014): planes seen as lines.

Design: ``docs/design/phantoms.md``, "Multi-wedge phantom".
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.phantom.features import (
    FeatureRows,
    PhantomResult,
    check_layout,
    fit_phantom,
    linear_start,
)
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
from brachycal.errors import DegenerateDataError, InputError
from brachycal.io import bundled
from brachycal.se3 import FloatArray, inverse

KIND = "multi-wedge"
#: The bundled default geometry (three printed roof wedges with ridges at −30°, 0° and +30°).
DEFAULT_GEOMETRY = ("phantoms", "multi_wedge.toml")
#: Half-length of the nominal line used for the layout check, metres (any non-zero length).
_HALF_LINE_M = 0.01


@dataclass(frozen=True)
class Face:
    """A planar face: ``point_m (3,)`` on it and unit ``normal (3,)``, phantom frame, metres."""

    name: str
    wedge: str
    point_m: FloatArray
    normal: FloatArray


@dataclass(frozen=True)
class WedgePhantom:
    """A multi-wedge phantom: its faces and the shared geometry (landmarks, reference body)."""

    faces: tuple[Face, ...]
    geometry: PhantomGeometry

    @property
    def names(self) -> list[str]:
        return [f.name for f in self.faces]

    def face(self, name: str) -> Face:
        return self.faces[self.names.index(name)]

    def nominal_rows(self) -> FeatureRows:
        """One nominal image's equations: the plane ``y = centroid`` cutting every face (layout check)."""
        centre = np.mean([f.point_m for f in self.faces], axis=0)
        uv, g, d = [], [], []
        for face in self.faces:
            n = face.normal
            line = np.cross(n, [0.0, 1.0, 0.0])  # the face's line in the plane y = const
            if np.linalg.norm(line) < 1e-9:
                raise DegenerateDataError(
                    f"{self.geometry.source}: face {face.name!r} is parallel to the image plane of the scan "
                    "(normal along y): the image never shows it as a line"
                )
            line /= np.linalg.norm(line)
            # The point of the face's line in y = centre[1] nearest the face's point (x-z plane).
            p = face.point_m + (centre[1] - face.point_m[1]) * np.array([0.0, 1.0, 0.0])
            p = p - (n @ (p - face.point_m)) / (n @ n - n[1] ** 2) * np.array([n[0], 0.0, n[2]])
            for end in (p - _HALF_LINE_M * line, p + _HALF_LINE_M * line):
                uv.append([end[0], -end[2]])  # image axes of the nominal scan: u along x, depth along −z
                g.append(n)
                d.append(n @ face.point_m)
        # Image frame = phantom axes (x, −z, y) at origin (0, centre_y, 0): written as rows in the phantom frame.
        R = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
        g_image = np.array(g) @ R
        d_image = np.array(d) - np.array(g) @ np.array([0.0, centre[1], 0.0])
        k = np.arange(len(uv))
        return FeatureRows(np.zeros(len(uv), dtype=int), np.array(uv), g_image, d_image, k)


def read_wedge_phantom(path: str | os.PathLike[str] | None = None) -> WedgePhantom:
    """Read a multi-wedge geometry (:mod:`brachycal.calibration.phantom.phantom_file`); default: the bundled one.

    Raises:
        InputError: a malformed file, a face without a proper normal, a repeated name.
        DegenerateDataError: fewer than two wedges, or faces that cannot fix the image plane.
    """
    path = bundled(*DEFAULT_GEOMETRY) if path is None else path
    data, geometry = load_toml(path, KIND)
    source = geometry.source
    where = None if source is None else Path(source)
    faces: list[Face] = []
    seen_wedges: set[str] = set()
    seen_faces: set[str] = set()
    wedges = entries(data, "wedge", where)
    for wedge in wedges:
        wedge_name = unique_name(wedge, "wedge", seen_wedges, where)
        for face in entries(wedge, "face", where):
            name = unique_name(face, "face", seen_faces, where)
            point = vector(face.get("point_mm"), f"face {name!r} point_mm", where) * MM
            normal = vector(face.get("normal"), f"face {name!r} normal", where, limit=None)
            length = np.linalg.norm(normal)
            if not length > 0:
                raise InputError(f"face {name!r} has a zero normal", file=where)
            faces.append(Face(name, wedge_name, point, normal / length))
    if len(wedges) < 2:
        raise DegenerateDataError(
            f"{source}: {len(wedges)} wedge(s): one wedge's two faces cannot fix the image plane "
            "(at least 2 wedges, with faces whose normals span 3D)"
        )
    phantom = WedgePhantom(tuple(faces), geometry)
    check_layout(phantom.nominal_rows(), "the wedges' faces", source)
    return phantom


def wedge_rows(phantom: WedgePhantom, observations: PhantomObservations) -> tuple[FeatureRows, FloatArray]:
    """The fit's equations (two per segmented line: its two ends) and ``T_phantom_marker (F, 4, 4)``."""
    faces = [phantom.face(name) for name in observations.feature]
    n = np.array([f.normal for f in faces])
    d = np.einsum("ki,ki->k", n, np.array([f.point_m for f in faces]))
    k = np.arange(len(faces))
    ends = observations.uv_px.shape[1]
    rows = FeatureRows(
        np.repeat(observations.frame, ends),
        observations.uv_px.reshape(-1, 2),
        np.repeat(n, ends, axis=0),
        np.repeat(d, ends),
        np.repeat(k, ends),
    )
    return rows, observations.T_phantom_marker(phantom.geometry.registration())


def check_lines(observations: PhantomObservations) -> None:
    """Refuse a segmented line whose two ends coincide (it gives no direction)."""
    length = np.linalg.norm(observations.uv_px[:, 1] - observations.uv_px[:, 0], axis=1)
    bad = np.flatnonzero(~(length > 0))
    if bad.size:
        k = int(bad[0])
        raise InputError(
            "the line's two ends are the same pixel: not a line", file=observations.source, row=observations.rows[k]
        )


def calibrate_wedge(phantom: WedgePhantom, observations: PhantomObservations) -> PhantomResult:
    """``T_marker_image`` with pixel spacings from a tracked multi-wedge session (module docstring).

    Raises:
        InputError: a line whose ends coincide.
        DegenerateDataError: too few frames, or data that cannot determine the fit.
        SolverError: the refinement does not converge.
    """
    check_lines(observations)
    rows, T_phantom_marker = wedge_rows(phantom, observations)
    return fit_phantom("wedge", rows, T_phantom_marker)


def calibrate_wedge_files(
    geometry: str | os.PathLike[str], observations: str | os.PathLike[str]
) -> tuple[PhantomResult, WedgePhantom, PhantomObservations]:
    """Read a geometry and an observations file and calibrate (the ``brachycal phantom wedge`` job)."""
    phantom = read_wedge_phantom(geometry)
    seen = read_observations(observations, KIND, phantom.names)
    return calibrate_wedge(phantom, seen), phantom, seen


def image_pose_in_phantom(phantom: WedgePhantom, faces: list[str], ends_px: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """One image's pose in the phantom, closed form: ``(T_phantom_image (4, 4), spacing_m (2,))``.

    Args:
        phantom: the geometry. faces: ``(K,)`` the faces seen.
        ends_px: ``(K, 2, 2)`` two points of each face's line, pixels.

    Raises:
        DegenerateDataError: fewer than five faces, or faces that do not fix the 9 linear unknowns.
    """
    ends = np.asarray(ends_px, dtype=float).reshape(len(faces), 2, 2)
    if len(faces) < 5:
        raise DegenerateDataError(
            f"{len(faces)} faces in one image: the closed-form pose and spacings need at least 5 (2 equations each)"
        )
    observations = PhantomObservations(
        ["image"], np.eye(4)[None], np.eye(4)[None], np.zeros(len(faces), dtype=int), list(faces), ends, []
    )
    rows, _ = wedge_rows(phantom, observations)
    T_phantom_image, spacing = linear_start(rows, np.eye(4)[None])
    return T_phantom_image, spacing


def lines_in_image(
    phantom: WedgePhantom, T_phantom_image: FloatArray, spacing_m: ArrayLike, u_px: ArrayLike
) -> FloatArray:
    """``(K, 2, 2)`` where each face's line shows at the columns ``u_px (K, 2)`` (exact, no beam): pixels.

    Used by the twin and the tests: for face ``k``, the image points at columns ``u`` whose
    phantom points lie on the face's plane.
    """
    T_image_phantom = inverse(T_phantom_image)
    s = np.asarray(spacing_m, dtype=float)
    u = np.asarray(u_px, dtype=float).reshape(len(phantom.faces), 2)
    out = np.empty((len(phantom.faces), 2, 2))
    for k, face in enumerate(phantom.faces):
        n_image = T_image_phantom[:3, :3] @ face.normal  # the plane in the image frame: n·p = c
        c = n_image @ (T_image_phantom[:3, :3] @ face.point_m + T_image_phantom[:3, 3])
        if abs(n_image[1]) < 1e-12:
            raise DegenerateDataError(f"face {face.name!r} is vertical in the image: no line v(u)")
        for j in range(2):
            x = u[k, j] * s[0]
            out[k, j] = [u[k, j], (c - n_image[0] * x) / n_image[1] / s[1]]
    return out
