"""What to plan: the sample grid, the insertion direction, the imaging geometry, the tools.

The paper (§III.C) takes 64 needle-tip positions evenly spread in a 40 mm cube covering the
prostate; for each, the probe moves so that its image shows the needle tip. brachycal aligns the
cube with the image frame at the reference probe pose: two cube axes lie in the image plane
(lateral u, depth v) and the third along the plane's normal. A grid point's in-plane offsets
decide where the tip appears in the image; its offset along the normal is taken up by moving
the probe along that normal. So each layer of the cube is one probe pose and the image points
fill a square of the image (Fig. 10 d of the paper), which keeps the registration well posed.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.session import MAX_SECTOR_DEPTH_M, ImageSector
from brachycal.errors import InputError
from brachycal.imaging.pixels import DEFAULT_IMAGE_SIZE_PX, DEFAULT_SPACING_M, image_points, pixels
from brachycal.se3 import FloatArray, inverse, make_transform
from brachycal.validate import (
    MAX_GRID_POINTS,
    MAX_IMAGE_PX,
    check_direction,
    check_int,
    check_range,
    check_spacing_m,
    check_vector,
)

if TYPE_CHECKING:  # types only: a spec loads without the robot model
    from brachycal.model.rig import Workspace
    from brachycal.model.robot import Robot

#: Cube edge, metres: at least 1 mm (a smaller cube puts grid points a few pixels apart, below what
#: 1 px annotation noise resolves), at most 0.5 m (far more than an image or a prostate covers).
EDGE_RANGE_M = (1e-3, 0.5)
#: Largest |coordinate| of the cube centre in ``base_link``, metres: four times the SDA10F's reach
#: (about 1.2 m per arm from the torso); a larger value is a unit slip (millimetres as metres).
MAX_CENTRE_M = 5.0
#: Largest margin the grid pixels may be asked to keep inside the field of view, metres.
MAX_FOV_MARGIN_M = 0.05


@dataclass(frozen=True)
class SectorFOV:
    """Sector field of view of a convex probe, in image pixels.

    Attributes:
        apex_px: ``(2,)`` pixel of the sector's apex (the transducer's centre).
        radius_m: depth of the sector, metres.
        angle_rad: full opening angle, symmetric about the image's +v (depth) direction.
    """

    apex_px: tuple[float, float] = (DEFAULT_IMAGE_SIZE_PX[0] / 2, 0.0)
    radius_m: float = 0.070
    angle_rad: float = np.radians(120.0)

    def __post_init__(self) -> None:
        # The apex of a convex probe may lie above the image (v < 0), so both signs are allowed.
        check_vector(self.apex_px, "sector apex (px)", 2, low=-MAX_IMAGE_PX, high=MAX_IMAGE_PX, unit="px")
        check_range(self.radius_m, "sector depth", low=0.0, high=MAX_SECTOR_DEPTH_M, low_open=True, unit="m")
        # Up to 180 deg: the distance to the straight edges below assumes half the angle <= 90 deg.
        check_range(self.angle_rad, "sector angle", low=0.0, high=np.pi, low_open=True, unit="rad")

    @classmethod
    def of(cls, sector: ImageSector) -> SectorFOV:
        """The geometry of a session's stated sector (:class:`~brachycal.data.session.ImageSector`)."""
        return cls(sector.apex_px, sector.depth_m, sector.angle_rad)

    def as_sector(self) -> ImageSector:
        """This sector as a session states it (``[image.sector]`` of ``session.toml``)."""
        return ImageSector((float(self.apex_px[0]), float(self.apex_px[1])), self.radius_m, float(self.angle_rad))

    def margin_to_edge(self, uv_px: ArrayLike, spacing_m: ArrayLike) -> FloatArray:
        """``(N,)`` distance in metres from each pixel to the sector's edge; negative outside."""
        return self.as_sector().margin_to_edge(uv_px, spacing_m)

    def outline_px(self, spacing_m: ArrayLike, n: int = 60) -> FloatArray:
        """``(M, 2)`` closed outline in pixels, for figures."""
        half = self.angle_rad / 2
        phi = np.linspace(-half, half, n)
        arc = np.column_stack([np.sin(phi), np.cos(phi)]) * self.radius_m / np.asarray(spacing_m) + self.apex_px
        return np.vstack([self.apex_px, arc, self.apex_px])


@dataclass(frozen=True)
class RectFOV:
    """Rectangular field of view of a linear probe: ``[u_min, u_max] × [v_min, v_max]`` pixels."""

    u_range_px: tuple[float, float] = (0.0, DEFAULT_IMAGE_SIZE_PX[0] - 1.0)
    v_range_px: tuple[float, float] = (0.0, DEFAULT_IMAGE_SIZE_PX[1] - 1.0)

    def __post_init__(self) -> None:
        for axis, bounds in (("u", self.u_range_px), ("v", self.v_range_px)):
            lo, hi = check_vector(bounds, f"rectangle {axis} range", 2, low=-0.5, high=MAX_IMAGE_PX, unit="px")
            if not lo < hi:
                raise InputError(f"rectangle {axis} range must go from low to high, got {lo:g}..{hi:g} px")

    def margin_to_edge(self, uv_px: ArrayLike, spacing_m: ArrayLike) -> FloatArray:
        uv = np.atleast_2d(np.asarray(uv_px, float))
        s = np.asarray(spacing_m)
        lo = np.array([self.u_range_px[0], self.v_range_px[0]])
        hi = np.array([self.u_range_px[1], self.v_range_px[1]])
        return np.min(np.minimum(uv - lo, hi - uv) * s, axis=1)

    def outline_px(self, spacing_m: ArrayLike, n: int = 5) -> FloatArray:
        (u0, u1), (v0, v1) = self.u_range_px, self.v_range_px
        return np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1], [u0, v0]])


def _unit(v: ArrayLike, name: str) -> FloatArray:
    return check_direction(v, name)


@dataclass(frozen=True)
class PlanSpec:
    """Inputs of the planner (SI units, directions in the robot's base frame, ``base_link`` on the SDA10F).

    The defaults of the cube centre and the three directions are the SDA10F's workspace
    (``robots/sda10f.toml``; a test keeps the two equal); :meth:`for_robot` takes another robot's.

    Attributes:
        cube_centre_m: ``(3,)`` centre of the sample cube (the prostate), metres.
        edge_m: cube edge, metres (paper: 0.040).
        points_per_axis: grid points per cube axis (paper: 4, so 64 samples).
        insertion_dir: ``(3,)`` needle direction (its tip frame's z axis), unit after normalising.
        image_depth_dir: ``(3,)`` direction of the image's +v (depth) at the reference probe pose.
        image_lateral_dir: ``(3,)`` direction of the image's +u (made perpendicular to depth).
        centre_px: ``(2,)`` pixel at which the cube centre appears.
        spacing_m: ``(2,)`` pixel spacing, metres.
        fov: the image's field of view (sector or rectangle).
        fov_margin_m: grid pixels must lie this far inside the field of view.
        offsets_m: ``(N, 3)`` sample points as offsets from the cube centre along the image's
            lateral, depth and normal axes, metres — a design other than the regular grid
            (``points_per_axis`` and ``edge_m`` then only describe the cube for targets).

    Every setting is checked on construction (NaN and infinity always refused): centre within
    :data:`MAX_CENTRE_M` of the base, edge in :data:`EDGE_RANGE_M`, 2 to 20 points per axis,
    non-zero directions with depth and lateral not parallel, centre pixel in [-0.5, 10000], a
    plausible ultrasound spacing (0.005..2 mm/px, given in metres), margin in [0, 50 mm].

    Raises:
        InputError: naming the setting, its range and the value given.
    """

    cube_centre_m: FloatArray = field(default_factory=lambda: np.array([0.80, 0.10, 1.05]))
    edge_m: float = 0.040
    points_per_axis: int = 4
    insertion_dir: FloatArray = field(
        default_factory=lambda: np.array([np.cos(np.radians(35.0)), np.sin(np.radians(35.0)), 0.0])
    )
    image_depth_dir: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    image_lateral_dir: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    centre_px: tuple[float, float] = (540.0, 221.0)
    spacing_m: FloatArray = field(default_factory=lambda: np.array(DEFAULT_SPACING_M))
    fov: SectorFOV | RectFOV = field(default_factory=SectorFOV)
    fov_margin_m: float = 0.002
    offsets_m: FloatArray | None = None

    def __post_init__(self) -> None:
        """Refuse any setting that is not finite and in range (every check fails on NaN).

        Raises:
            InputError: naming the setting, its accepted range and the value given.
        """
        check_vector(self.cube_centre_m, "cube centre", 3, low=-MAX_CENTRE_M, high=MAX_CENTRE_M, unit="m")
        check_range(self.edge_m, "cube edge", low=EDGE_RANGE_M[0], high=EDGE_RANGE_M[1], unit="m")
        check_int(self.points_per_axis, "points per axis", low=2, high=MAX_GRID_POINTS)
        _unit(self.insertion_dir, "insertion direction")
        self.image_axes()  # both image directions non-zero and not parallel
        check_vector(self.centre_px, "centre pixel", 2, low=-0.5, high=MAX_IMAGE_PX, unit="px")
        check_spacing_m(self.spacing_m, "pixel spacing")
        if not isinstance(self.fov, (SectorFOV, RectFOV)):
            raise InputError(f"field of view must be a SectorFOV or a RectFOV, got {type(self.fov).__name__}")
        check_range(self.fov_margin_m, "field-of-view margin", low=0.0, high=MAX_FOV_MARGIN_M, unit="m")
        if self.offsets_m is not None:
            offsets = np.asarray(self.offsets_m, dtype=float)
            if offsets.ndim != 2 or offsets.shape[1] != 3 or not 1 <= len(offsets) <= MAX_GRID_POINTS**3:
                raise InputError(
                    f"sample offsets must be (N, 3) with 1 <= N <= {MAX_GRID_POINTS**3}, got {offsets.shape}"
                )
            if not np.all(np.abs(offsets) <= EDGE_RANGE_M[1]):  # also refuses NaN
                raise InputError(f"sample offsets must be finite and within {EDGE_RANGE_M[1]:g} m of the cube centre")

    @classmethod
    def for_robot(cls, robot: Robot, **changes: Any) -> PlanSpec:
        """The spec of ``robot``'s workspace (``robot.rig.workspace``: cube centre, insertion and image
        directions), with ``changes`` (any other field, or one of those) on top.

        Raises:
            InputError: the robot has no rig, or a change is out of range.
        """
        return cls.for_workspace(robot.rig.workspace, **changes)

    @classmethod
    def for_workspace(cls, workspace: Workspace, **changes: Any) -> PlanSpec:
        """The spec of a rig's :class:`~brachycal.model.rig.Workspace`, with ``changes`` on top."""
        spec = cls(
            cube_centre_m=np.array(workspace.cube_centre_m),
            insertion_dir=np.array(workspace.insertion_dir),
            image_depth_dir=np.array(workspace.image_depth_dir),
            image_lateral_dir=np.array(workspace.image_lateral_dir),
        )
        return replace(spec, **changes) if changes else spec

    def image_axes(self) -> FloatArray:
        """``R_base_image (3, 3)`` of the reference probe pose: columns x (u), y (v), z = x × y."""
        y = _unit(self.image_depth_dir, "image depth direction")
        x = _unit(self.image_lateral_dir, "image lateral direction")
        x = x - (x @ y) * y
        if np.linalg.norm(x) < 1e-6:
            raise InputError("image lateral and depth directions are parallel")
        x /= np.linalg.norm(x)
        return np.column_stack([x, y, np.cross(x, y)])

    def grid(self) -> tuple[np.ndarray, FloatArray, FloatArray, FloatArray]:
        """The samples: ``(index (N, 3) ints, p_base (N, 3), uv_px (N, 2), normal_offset_m (N,))``.

        Indices ``(i, j, k)`` count along the image's lateral, depth and normal axes.
        """
        if self.offsets_m is not None:
            offsets = np.asarray(self.offsets_m, dtype=float).reshape(-1, 3)
            # dense ranks along each axis stand in for grid indices (ordering, point names)
            index = np.column_stack([np.unique(np.round(offsets[:, a], 9), return_inverse=True)[1] for a in range(3)])
        else:
            n = self.points_per_axis
            steps = (np.arange(n) - (n - 1) / 2) * self.edge_m / (n - 1)
            index = np.array([(i, j, k) for k in range(n) for j in range(n) for i in range(n)])
            offsets = steps[index]  # (N, 3) along image x, y, z
        R = self.image_axes()
        p_base = self.cube_centre_m + offsets @ R.T
        uv = np.asarray(self.centre_px) + pixels(offsets, self.spacing_m)
        return index, p_base, uv, offsets[:, 2]

    def image_pose(self, normal_offset_m: float) -> FloatArray:
        """``T_base_image (4, 4)`` for a layer: the cube centre at :attr:`centre_px`, shifted along the normal."""
        R = self.image_axes()
        centre_in_image = image_points(self.centre_px, self.spacing_m)[0]
        origin = self.cube_centre_m + normal_offset_m * R[:, 2] - R @ centre_in_image
        return make_transform(R, origin)

    def probe_pose(self, normal_offset_m: float, T_Ptip_I: ArrayLike) -> FloatArray:
        """``T_base_probe (4, 4)`` that puts the image where :meth:`image_pose` says."""
        return self.image_pose(normal_offset_m) @ inverse(np.asarray(T_Ptip_I))

    def needle_pose(self, p_base: ArrayLike) -> FloatArray:
        """``T_base_needle (4, 4)`` target: tip at ``p_base``, z along the insertion direction.

        The roll about the needle is free in the planner; this sets one (x ⟂ z, towards base +z).
        """
        z = _unit(self.insertion_dir, "insertion direction")
        helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        x = helper - (helper @ z) * z
        x /= np.linalg.norm(x)
        return make_transform(np.column_stack([x, np.cross(z, x), z]), p_base)
