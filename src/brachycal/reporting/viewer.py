"""An interactive 3D view in the browser: the robot at a pose or along a set of poses, its tool
frames and image plane, sample points with their residual vectors, the sample cube, targets and
where the needle landed. Its side panel has a legend (what each colour is), a readout (the
calibration shown, the frame and units, the chosen sample's residual) and a checkbox per layer; the
first view frames the whole scene, the robot's base included.

Served by `viser <https://viser.studio>`_: a maintained WebGL viewer whose client ships inside
the pip package (no Node, no second server), which loads the robot's meshes through yourdfpy (the
loader :mod:`brachycal.reporting.scene` already uses, so the view shows the same geometry the
kinematics compute with), steps through poses with a slider, and shows inside Jupyter (an IFrame
of the same page, :meth:`Viewer.show`). Pinocchio's Meshcat visualizer was the alternative; its
client, meshcat-python, has had no release since 2021.

:class:`ViewContent` is what is shown (plain arrays, built and tested without a browser);
:class:`Viewer` serves it. Everything is in the robot's base frame, metres.
"""

from __future__ import annotations

import html
import socket
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.labels import ALL_LABELS
from brachycal.calibration.result import locate
from brachycal.errors import InputError
from brachycal.imaging.pixels import image_points
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, transform_points
from brachycal.studies.targeting import targeting_error

if TYPE_CHECKING:
    import viser

    from brachycal.calibration.session.result_file import ResultFile
    from brachycal.data.session import Session
    from brachycal.simulation.twin import Twin

#: Colours (RGB, 0–255) of what the view draws, so that a screenshot can be checked by colour.
ROBOT_RGB = (150, 160, 190)
IMAGE_RGB = (255, 160, 0)
#: None is close (within 80 per channel) to another one or to the frames' axes (red, green, blue).
COLOURS: dict[str, tuple[int, int, int]] = {
    "real": (200, 0, 90),  # crimson: needle tips through the needle arm
    "calibrated": (0, 150, 200),  # teal: the same tips through the probe arm and the image
    "residual": (20, 20, 20),
    "target": (120, 200, 40),  # lime
    "landed": (230, 0, 230),  # magenta
    "cube": (120, 120, 120),
}
#: Tool frames drawn as axes at each pose.
VIEW_FRAMES = (NEEDLE_TIP, PROBE_TIP, US_IMAGE)
#: Layer → (its name in the panel, what it is): the legend's words and the checkboxes' labels.
#: ``points/<name>`` and ``vectors/<name>`` are drawn in :data:`COLOURS` [name].
LEGEND: dict[str, tuple[str, str]] = {
    "robot": ("robot", "the robot's links at the chosen pose"),
    "frames": ("tool frames", "needle tip, probe tip and image frames (x red, y green, z blue)"),
    "image_plane": ("image plane", "the ultrasound image at the chosen pose, where the calibration puts it"),
    "points/real": ("needle tips, measured", "through the needle arm's kinematics"),
    "points/calibrated": ("needle tips, calibrated", "through the probe arm and the image calibration"),
    "vectors/residual": ("residuals", "each sample's measured tip joined to its calibrated one"),
    "cube": ("sample cube", "where the samples were planned, aligned with the image"),
    "points/target": ("targets", "points the needle was sent to"),
    "points/landed": ("needle landed", "where the needle tip landed, commanded through the calibration"),
    "vectors/landed": ("targeting errors", "each target joined to where the needle landed"),
}
#: The first view: the camera looks at the scene from this direction (base frame: from the robot's
#: front-right, above), with this vertical field of view, and frames the whole scene in any window
#: at least :data:`VIEW_MIN_ASPECT` wide (width / height of the 3D canvas; the side panel docks to
#: the right and is not part of it); the scene fills at most :data:`VIEW_FILL` of it.
VIEW_DIRECTION = (1.0, -1.2, 0.6)
VIEW_FOV_RAD = float(np.radians(50.0))
VIEW_MIN_ASPECT = 0.75
VIEW_FILL = 0.85


@dataclass(frozen=True)
class Layer:
    """One layer of the view: its key in :data:`LEGEND`, name, meaning, and colour (RGB 0–255;
    None: drawn in several, the frames' axes)."""

    key: str
    label: str
    meaning: str
    rgb: tuple[int, int, int] | None


@dataclass(frozen=True)
class ViewContent:
    """What the view shows, in the robot's base frame (metres).

    Attributes:
        robot: the model drawn (with the calibrated tool frames, if any).
        poses_q: ``(M, nq)`` configurations the slider steps through (M ≥ 1), radians.
        pose_labels: ``(M,)`` a name per pose (sample or plan point names).
        image_size_px: ``(width, height)`` of the image drawn on ``us_image``; None: no image plane.
        spacing_m: ``(2,)`` pixel spacing of that image, metres per pixel.
        points: name → ``(K, 3)`` points, drawn in :data:`COLOURS` [name].
        vectors: name → ``((K, 3), (K, 3))`` segments from the first to the second point.
        cube: ``(T_base_cube (4, 4), edge_m)``: the sample cube, axes along ``T``'s; None: none.
        calibration: the calibration shown, in words (method, its name, the solve); None: none.
    """

    robot: Robot
    poses_q: FloatArray
    pose_labels: list[str]
    image_size_px: tuple[int, int] | None = None
    spacing_m: FloatArray = field(default_factory=lambda: np.array([1.9e-4, 1.9e-4]))
    points: dict[str, FloatArray] = field(default_factory=dict)
    vectors: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    cube: tuple[FloatArray, float] | None = None
    calibration: str | None = None

    def __post_init__(self) -> None:
        q = np.atleast_2d(np.asarray(self.poses_q, dtype=float))
        if q.shape[1] != self.robot.nq or len(q) == 0:
            raise InputError(f"poses must be (M, {self.robot.nq}) configurations, got shape {q.shape}")
        if len(self.pose_labels) != len(q):
            raise InputError(f"{len(self.pose_labels)} pose labels for {len(q)} poses")
        object.__setattr__(self, "poses_q", q)

    def image_corners_m(self, k: int) -> FloatArray | None:
        """``(4, 3)`` corners of the image plane at pose ``k``; None without an image size."""
        if self.image_size_px is None:
            return None
        w, h = self.image_size_px
        corners_px = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=float)
        return transform_points(self.robot.fk(US_IMAGE, self.poses_q[k]), image_points(corners_px, self.spacing_m))

    def layers(self) -> list[Layer]:
        """The layers this content draws, in :data:`LEGEND`'s order."""
        shown = {"robot", "frames"}
        shown |= {"image_plane"} if self.image_size_px is not None else set()
        shown |= {"cube"} if self.cube is not None else set()
        shown |= {f"points/{name}" for name in self.points} | {f"vectors/{name}" for name in self.vectors}
        keys = [k for k in LEGEND if k in shown] + sorted(shown - set(LEGEND))
        colours = {"robot": ROBOT_RGB, "image_plane": IMAGE_RGB, "cube": COLOURS["cube"], "frames": None}
        return [
            Layer(k, *LEGEND.get(k, (k, "")), colours.get(k, COLOURS.get(k.partition("/")[2], (0, 0, 0)))) for k in keys
        ]

    def residuals_mm(self) -> FloatArray | None:
        """``(M,)`` each pose's residual, millimetres: the length of its ``residual`` vector (the
        needle tip through the needle arm to the same tip through the probe arm and the image);
        None without one residual per pose."""
        if "residual" not in self.vectors:
            return None
        a, b = self.vectors["residual"]
        if len(a) != len(self.poses_q):
            return None
        return np.linalg.norm(np.asarray(b, dtype=float) - np.asarray(a, dtype=float), axis=1) * 1e3

    def readout(self) -> str:
        """The panel's summary (Markdown): the calibration shown, the frame and units, and the RMS
        of the residuals."""
        lines = [f"**Calibration:** {self.calibration or 'none (the robot model only)'}"]
        lines.append(f"**Frame:** `{self.robot.rig.base}` (the robot's base); positions in metres")
        residuals = self.residuals_mm()
        if residuals is not None:
            rms = float(np.sqrt(np.mean(residuals**2)))
            lines.append(f"**Residuals:** RMS {rms:.3f} mm over {len(residuals)} samples, max {residuals.max():.3f} mm")
        return "  \n".join(lines)

    def sample_readout(self, k: int) -> str:
        """Pose ``k``'s residual in words (millimetres), or "" without residuals."""
        residuals = self.residuals_mm()
        return "" if residuals is None else f"{residuals[k]:.3f} mm"

    def scene_points_m(self) -> FloatArray:
        """``(N, 3)`` every point drawn but the robot's meshes (points, segment ends, cube corners,
        tool frame origins and image corners at every pose), metres: what the first view frames."""
        parts = [np.asarray(p, dtype=float).reshape(-1, 3) for p in self.points.values()]
        parts += [np.asarray(e, dtype=float).reshape(-1, 3) for pair in self.vectors.values() for e in pair]
        if self.cube is not None:
            parts += list(cube_edges(*self.cube))
        parts += [self.robot.fk(f, self.poses_q)[..., :3, 3].reshape(-1, 3) for f in VIEW_FRAMES]
        for k in range(len(self.poses_q)):
            corners = self.image_corners_m(k)
            if corners is not None:
                parts.append(corners)
        return np.concatenate(parts)


def cube_edges(T_base_cube: ArrayLike, edge_m: float) -> tuple[FloatArray, FloatArray]:
    """The 12 edges of a cube centred on ``T_base_cube``'s origin: ``(12, 3)`` starts and ends."""
    corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float) * edge_m / 2
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(corners[a] != corners[b]) == 1]
    p = transform_points(np.asarray(T_base_cube, dtype=float), corners)
    return p[[a for a, _ in pairs]], p[[b for _, b in pairs]]


def frame_camera(
    points_m: ArrayLike,
    *,
    direction: ArrayLike = VIEW_DIRECTION,
    up: ArrayLike = (0.0, 0.0, 1.0),
    fov_rad: float = VIEW_FOV_RAD,
    aspect: float = VIEW_MIN_ASPECT,
    fill: float = VIEW_FILL,
) -> tuple[FloatArray, FloatArray]:
    """A camera that sees every point: ``(position (3,), look_at (3,))``, metres.

    It looks at the centre of the points' bounding box from ``direction`` (towards the camera),
    ``up`` being the screen's up, and stands as close as it can with every point inside ``fill``
    of a perspective view of vertical field of view ``fov_rad`` (radians) and width / height
    ``aspect``; a wider window sees more, so it holds for every window at least that wide.

    Args:
        points_m: ``(N, 3)`` points to frame (N ≥ 1).
    """
    p = np.asarray(points_m, dtype=float).reshape(-1, 3)
    look_at = (p.min(axis=0) + p.max(axis=0)) / 2
    back = np.asarray(direction, dtype=float)
    back = back / np.linalg.norm(back)  # from the point looked at towards the camera
    right = np.cross(-back, np.asarray(up, dtype=float))
    right /= np.linalg.norm(right)
    screen_up = np.cross(right, -back)
    rel = p - look_at
    x, y, towards = np.abs(rel @ right), np.abs(rel @ screen_up), rel @ back
    tan_v = fill * np.tan(fov_rad / 2)
    tan_h = fill * aspect * np.tan(fov_rad / 2)
    # A point at depth d = D - towards in front of a camera D away is in view if |x| <= d tan_h
    # and |y| <= d tan_v: D is the least distance that holds for every point (and 1 mm in front).
    distance = float(np.max(np.maximum(np.maximum(x / tan_h, y / tan_v), 1e-3) + towards))
    return look_at + distance * back, look_at


class Viewer:
    """The content served in the browser; the page is at :attr:`url` until :meth:`close`.

    Args:
        content: what to show.
        host: interface to listen on (``127.0.0.1``: this machine only; ``0.0.0.0``: the network).
        port: TCP port; 0 picks a free one.
    """

    def __init__(self, content: ViewContent, host: str = "127.0.0.1", port: int = 0) -> None:
        import viser  # lazy: start-up (viser)

        if port == 0:
            port = _free_port(host)
        self.content = content
        self.server: viser.ViserServer = viser.ViserServer(host=host, port=port, label="brachycal", verbose=False)
        self.host, self.port = host, self.server.get_port()  # viser moves to the next port if one is taken
        try:
            self._build()
        except OSError as exc:  # a mesh that will not load: named as such (not as a server problem)
            self.server.stop()
            where = f"{exc.filename}: " if exc.filename else ""
            raise InputError(f"cannot load the robot's meshes for the view: {where}{exc.strerror or exc}") from None
        except BaseException:  # no server left running
            self.server.stop()
            raise

    def _build(self) -> None:
        from viser.extras import ViserUrdf  # lazy: start-up (viser)

        from brachycal.reporting.scene import load_urdf, robot_bounds  # lazy: start-up (yourdfpy, matplotlib)

        content = self.content
        scene, gui = self.server.scene, self.server.gui
        scene.set_up_direction("+z")
        gui.main_panel.dock_right()  # beside the 3D canvas, not over it: the first view is all seen
        robot = content.robot
        self._urdf = ViserUrdf(self.server, load_urdf(robot), root_node_name="/robot", mesh_color_override=ROBOT_RGB)
        self._joint_order = self._urdf.get_actuated_joint_names()
        self._frames = {f: scene.add_frame(f"/frames/{f}", axes_length=0.05, axes_radius=0.002) for f in VIEW_FRAMES}
        self._image: Any = None
        nodes: dict[str, list[Any]] = {"robot": [], "frames": list(self._frames.values()), "image_plane": []}
        for name, p in content.points.items():
            nodes[f"points/{name}"] = [
                scene.add_point_cloud(
                    f"/points/{name}",
                    points=np.asarray(p, dtype=float),
                    colors=COLOURS.get(name, (0, 0, 0)),
                    point_size=0.004,
                    point_shape="circle",
                )
            ]
        for name, (a, b) in content.vectors.items():
            segments = np.stack([np.asarray(a, dtype=float), np.asarray(b, dtype=float)], axis=1)
            nodes[f"vectors/{name}"] = [
                scene.add_line_segments(
                    f"/vectors/{name}",
                    points=segments,
                    colors=COLOURS.get(name, (0, 0, 0)),
                    thickness=2.0,
                    thickness_units="screen",
                )
            ]
        if content.cube is not None:
            a, b = cube_edges(*content.cube)
            nodes["cube"] = [
                scene.add_line_segments(
                    "/cube",
                    points=np.stack([a, b], axis=1),
                    colors=COLOURS["cube"],
                    thickness=1.5,
                    thickness_units="screen",
                )
            ]
        self.readout = gui.add_markdown(content.readout())
        self._slider = gui.add_slider(
            "pose",
            min=0,
            max=max(len(content.poses_q) - 1, 1),
            step=1,
            initial_value=0,
            disabled=len(content.poses_q) == 1,
        )
        self._label = gui.add_text("name", initial_value=content.pose_labels[0], disabled=True)
        self._residual = (
            gui.add_text("residual", initial_value="", disabled=True) if content.residuals_mm() is not None else None
        )
        #: Layer key → its checkbox (checked: shown).
        self.toggles: dict[str, Any] = {}
        with gui.add_folder("Layers"):
            for layer in content.layers():
                box = gui.add_checkbox(layer.label, initial_value=True, hint=layer.meaning)
                box.on_update(partial(self._toggle, layer.key))
                self.toggles[layer.key] = box
        self._nodes = nodes
        with gui.add_folder("Legend"):
            #: The legend as shown (HTML): a colour swatch, the layer's name and what it is, per layer.
            self.legend = gui.add_html(legend_html(content.layers()))
        self._slider.on_update(lambda _: self.show_pose(int(self._slider.value)))
        self.show_pose(0)
        bounds = robot_bounds(robot, content.poses_q)
        corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
        position, look_at = frame_camera(np.concatenate([corners, content.scene_points_m()]))
        self.server.initial_camera.fov = VIEW_FOV_RAD
        self.server.initial_camera.look_at = tuple(look_at)
        self.server.initial_camera.position = tuple(position)

    def _toggle(self, key: str, _event: object = None) -> None:
        """Show or hide layer ``key`` as its checkbox says."""
        visible = bool(self.toggles[key].value)
        if key == "robot":
            self._urdf.show_visual = visible
        if key == "image_plane" and self._image is not None:
            self._image.visible = visible
        for node in self._nodes.get(key, []):
            node.visible = visible

    @property
    def url(self) -> str:
        """The page's address."""
        host = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        return f"http://{host}:{self.port}"

    def show_pose(self, k: int) -> None:
        """Put the robot, its tool frames and the image plane at pose ``k``."""
        content = self.content
        q = content.poses_q[k]
        named = content.robot.named(q)
        self._urdf.update_cfg(np.array([named[n] for n in self._joint_order], dtype=float))
        for frame, handle in self._frames.items():
            T = content.robot.fk(frame, q)
            handle.position = T[:3, 3]
            handle.wxyz = _wxyz(T[:3, :3])
        corners = content.image_corners_m(k)
        if corners is not None:
            if self._image is not None:
                self._image.remove()
            self._image = self.server.scene.add_mesh_simple(
                "/image_plane",
                vertices=corners,
                faces=np.array([[0, 1, 2], [0, 2, 3]]),
                color=IMAGE_RGB,
                opacity=0.5,
                side="double",
                visible=bool(self.toggles["image_plane"].value) if "image_plane" in self.toggles else True,
            )
        self._label.value = content.pose_labels[k]  # type: ignore[misc]  # viser has the setter; mypy sees the base's getter only
        if self._residual is not None:
            self._residual.value = content.sample_readout(k)  # type: ignore[misc]  # as above

    def show(self, height: int = 600) -> Any:
        """The view in a Jupyter notebook (an IFrame of :attr:`url`)."""
        from IPython.display import IFrame  # lazy: start-up (IPython)

        return IFrame(self.url, width="100%", height=height)

    def close(self) -> None:
        """Stop serving."""
        self.server.stop()


def legend_html(layers: Sequence[Layer]) -> str:
    """The legend (HTML): per layer a swatch of its colour, its name and what it is."""
    rows = []
    for layer in layers:
        if layer.rgb is None:  # the frames: their three axes' colours
            swatch = "".join(_swatch(c) for c in ((220, 0, 0), (0, 180, 0), (0, 0, 220)))
        else:
            swatch = _swatch(layer.rgb)
        label, meaning = html.escape(layer.label, quote=False), html.escape(layer.meaning, quote=False)
        rows.append(f"<div style='margin:2px 0'>{swatch} <b>{label}</b>: {meaning}</div>")
    return "<div style='font-size:0.85em;padding:0 0.5em'>" + "".join(rows) + "</div>"


def _swatch(rgb: tuple[int, int, int]) -> str:
    r, g, b = rgb
    return f"<span style='display:inline-block;width:0.9em;height:0.9em;background:rgb({r},{g},{b})'></span>"


def _wxyz(R: FloatArray) -> tuple[float, float, float, float]:
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return (float(w), float(x), float(y), float(z))


def _free_port(host: str) -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def poses_content(
    robot: Robot,
    poses_q: ArrayLike,
    labels: Sequence[str] | None = None,
    *,
    image_size_px: tuple[int, int] | None = None,
    spacing_m: ArrayLike = (1.9e-4, 1.9e-4),
) -> ViewContent:
    """The robot stepping through ``poses_q`` ``(M, nq)`` (a plan, a log), nothing else."""
    q = np.atleast_2d(np.asarray(poses_q, dtype=float))
    names = list(labels) if labels is not None else [str(k) for k in range(len(q))]
    return ViewContent(robot, q, names, image_size_px, np.asarray(spacing_m, dtype=float))


def calibration_content(
    robot: Robot,
    stored: ResultFile,
    session: Session,
    method: str,
    *,
    twin: Twin | None = None,
    n_targets: int = 50,
) -> ViewContent:
    """A calibrated session: the robot through its samples, and per sample the needle tip through
    the needle arm (``real``: ``T_R_ER(q) @ p_ER_Ntip``) and through the probe arm and the image
    (``calibrated``: ``T_R_EL(q) @ T_EL_Ptip @ T_Ptip_I @ p_I``, Fig. 10's pair) joined by their
    ``residual``; the calibration in words (:func:`calibration_said`); the sample cube, aligned
    with the image as the planner aligns it. With the twin the session was simulated by, also
    ``target`` and ``landed`` points (the end-to-end targeting error,
    :func:`~brachycal.studies.targeting_error`, with the model the software commands).

    Raises:
        InputError: ``method`` is not in the result.
    """
    calibration = stored.calibration(method)
    image = calibration.image
    software = stored.software_robot(robot)
    shown = calibration.robot(software)
    q = session.samples_q
    real = transform_points(software.fk(robot.rig.needle_flange, q), stored.T_ER_Ntip[:3, 3])
    calibrated = locate(software, q, session.uv_px, calibration)
    points = {"real": real, "calibrated": calibrated}
    vectors = {"residual": (real, calibrated)}
    # The planner aligns the cube with the image at the first pose: its axes are the image's.
    T_cube = shown.fk(US_IMAGE, q[0]).copy()
    T_cube[:3, 3] = real.mean(axis=0)
    extent = np.ptp((real - T_cube[:3, 3]) @ T_cube[:3, :3], axis=0)
    cube = (T_cube, float(max(extent.max(), 1e-3)))
    if twin is not None:
        hit = targeting_error(twin, calibration, n_targets, software=software)
        points["target"], points["landed"] = hit.targets_m, hit.landed_m
        vectors["landed"] = (hit.targets_m, hit.landed_m)
    size = (int(session.size_px[0]), int(session.size_px[1]))
    said = calibration_said(stored, method)
    return ViewContent(shown, q, list(session.sample_ids), size, image.spacing_m, points, vectors, cube, said)


def calibration_said(stored: ResultFile, method: str) -> str:
    """Image calibration ``method`` of ``stored`` in words: the method and its name, the solve
    that gave it as the result names it (``sequential``: tools first, then the image
    registration; ``chain``: the whole chain at once), and the robot corrections it carries."""
    solve = "chain" if method in ("chain", "chain+robot") else "sequential"
    corrections = stored.corrections()
    carried = f"; robot corrected ({', '.join(corrections)})" if corrections else ""
    return f"{method} ({ALL_LABELS.get(method, method)}), {solve} solve{carried}"
