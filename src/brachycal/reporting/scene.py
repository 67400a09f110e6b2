"""A 3D scene of the robot at a configuration, with tool frames and the image plane.

Built with yourdfpy/trimesh from the same URDF the kinematics use (the vendor's light collision
meshes), so what is drawn is what is computed. It can be shown in a notebook
(``scene.show()``), saved as a self-contained binary glTF (``.glb``, opens in any glTF viewer,
Blender, 3D Slicer), or drawn by matplotlib (no OpenGL needed) as a figure
(:func:`scene_figure`) or a PNG (:func:`render_png`), without touching pyplot or the backend.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from functools import partial
from pathlib import Path

import numpy as np
import trimesh
import yourdfpy
from matplotlib.figure import Figure
from numpy.typing import ArrayLike
from trimesh.visual import ColorVisuals, TextureVisuals

from brachycal.imaging.pixels import DEFAULT_IMAGE_SIZE_PX, DEFAULT_SPACING_M, image_points
from brachycal.io import atomic_path
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.reporting.figures import save_figure
from brachycal.se3 import FloatArray, transform_points

TOOL_FRAMES = (NEEDLE_TIP, PROBE_TIP, US_IMAGE)


def load_urdf(robot: Robot) -> yourdfpy.URDF:
    """The robot's URDF with its meshes (paths relative to the URDF's folder), as yourdfpy loads it."""
    return yourdfpy.URDF.load(
        io.StringIO(robot.urdf_xml),
        filename_handler=partial(yourdfpy.filename_handler_relative, dir=str(robot.base_dir)),
    )


def robot_scene(
    robot: Robot,
    q: ArrayLike,
    *,
    frames: Sequence[str] = TOOL_FRAMES,
    image_size_px: tuple[int, int] | None = DEFAULT_IMAGE_SIZE_PX,
    spacing_m: ArrayLike = DEFAULT_SPACING_M,
    points_m: ArrayLike | None = None,
) -> trimesh.Scene:
    """The robot at ``q`` (``(nq,)``), axes on ``frames``, the image rectangle, optional points ``(K, 3)``."""
    q = np.asarray(q, dtype=float)
    urdf = load_urdf(robot)
    urdf.update_cfg(robot.named(q))
    scene = urdf.scene.copy()
    for frame in frames:
        axis = trimesh.creation.axis(origin_size=0.004, axis_radius=0.002, axis_length=0.05)
        scene.add_geometry(axis, node_name=f"{frame}_axes", geom_name=f"{frame}_axes", transform=robot.fk(frame, q))
    for tool, colour in ((NEEDLE_TIP, [200, 200, 200, 255]), (PROBE_TIP, [60, 60, 60, 255])):
        flange = robot.rig.tool_frame_parents[tool]  # the arm's flange (the rig's: any robot)
        # The end-effectors have no geometry in the URDF: draw each as a rod from flange to tip.
        a, b = robot.fk(flange, q)[:3, 3], robot.fk(tool, q)[:3, 3]
        radius = 0.004 if tool == NEEDLE_TIP else 0.009
        rod = trimesh.creation.cylinder(radius=radius, segment=np.stack([a, b]), face_colors=colour)
        scene.add_geometry(rod, node_name=f"{tool}_rod", geom_name=f"{tool}_rod")
    if image_size_px is not None:
        w, h = image_size_px
        corners_px = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=float)
        p = transform_points(robot.fk(US_IMAGE, q), image_points(corners_px, spacing_m))
        faces = [[0, 1, 2], [0, 2, 3], [2, 1, 0], [3, 2, 0]]
        plane = trimesh.Trimesh(vertices=p, faces=faces, process=False, face_colors=[255, 160, 0, 120])
        scene.add_geometry(plane, node_name="us_image_plane", geom_name="us_image_plane")
    if points_m is not None:
        for k, point in enumerate(np.atleast_2d(points_m)):
            ball = trimesh.creation.icosphere(subdivisions=1, radius=0.0015, face_colors=[200, 30, 30, 255])
            place = trimesh.transformations.translation_matrix(point)
            scene.add_geometry(ball, node_name=f"point_{k}", geom_name=f"point_{k}", transform=place)
    return scene


def robot_bounds(robot: Robot, poses_q: ArrayLike) -> FloatArray:
    """``(2, 3)`` low and high corners of the box holding the robot's meshes at every pose of
    ``poses_q`` (``(M, nq)``, radians), in the robot's base frame, metres."""
    urdf = load_urdf(robot)
    boxes = []
    for q in np.atleast_2d(np.asarray(poses_q, dtype=float)):
        urdf.update_cfg(robot.named(q))
        boxes.append(np.asarray(urdf.scene.bounds, dtype=float))
    return np.array([np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)])


def save_glb(scene: trimesh.Scene, path: str | os.PathLike[str]) -> Path:
    """Write the scene as one self-contained binary glTF file (atomically; replaces an existing one)."""
    data = scene.export(file_type="glb")
    with atomic_path(path, force=True) as staged:
        staged.write_bytes(data)
    return Path(path)


def _face_colours(mesh: trimesh.Trimesh) -> np.ndarray:
    """``(F, 4)`` RGBA (0–255) of each face; a textured mesh (a URDF may use one) by its texture's colours."""
    visual = mesh.visual
    if isinstance(visual, TextureVisuals):
        visual = visual.to_color()
    if visual is None:  # trimesh gives every Trimesh a visual; one built without has trimesh's default colour
        visual = ColorVisuals(mesh)
    return np.asarray(visual.face_colors)


def scene_figure(
    scene: trimesh.Scene,
    *,
    elevation: float = 20.0,
    azimuth: float = -60.0,
    zoom_to: ArrayLike | None = None,
) -> Figure:
    """A matplotlib drawing of the scene's triangles (flat shaded), axes in metres.

    Args:
        scene: from :func:`robot_scene`.
        elevation: view angle, degrees (matplotlib's ``view_init``).
        azimuth: view angle, degrees.
        zoom_to: ``(2, 3)`` low and high corners of the box to show, metres; default the whole scene.
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # lazy: start-up (mpl_toolkits)

    fig = Figure(figsize=(7, 6), layout="tight")
    ax = fig.add_subplot(projection="3d")
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    lows, highs = [], []
    for name in scene.graph.nodes_geometry:
        transform, geometry_name = scene.graph[name]
        mesh = scene.geometry[geometry_name]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        vertices = transform_points(transform, mesh.vertices)
        triangles = vertices[mesh.faces]
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        face_rgba = _face_colours(mesh)
        base = np.asarray(face_rgba[:, :3], dtype=float) / 255.0
        shade = 0.45 + 0.55 * np.abs(normals @ light)
        colours = np.clip(base * shade[:, None], 0, 1)
        alpha = face_rgba[:, 3] / 255.0
        ax.add_collection3d(Poly3DCollection(triangles, facecolors=np.column_stack([colours, alpha]), linewidths=0))
        lows.append(vertices.min(axis=0))
        highs.append(vertices.max(axis=0))
    low, high = (np.min(lows, axis=0), np.max(highs, axis=0)) if zoom_to is None else np.asarray(zoom_to, float)
    centre, half = (low + high) / 2, np.max(high - low) / 2
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elevation, azim=azimuth)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    return fig


def render_png(
    scene: trimesh.Scene,
    path: str | os.PathLike[str],
    *,
    elevation: float = 20.0,
    azimuth: float = -60.0,
    zoom_to: ArrayLike | None = None,
) -> Path:
    """Save :func:`scene_figure` as the PNG ``path`` (100 dpi)."""
    save_figure(scene_figure(scene, elevation=elevation, azimuth=azimuth, zoom_to=zoom_to), path, dpi=100)
    return Path(path)
