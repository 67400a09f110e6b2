"""Writers (and readers, for round trips) of the formats a calibration is used in.

- **URDF** (``<robot>_calibrated.urdf``, ``<robot>`` the description's name: ``sda10f``,
  ``ur5_pair``, ...): the robot's URDF with the calibrated ``needle_tip``, ``probe_tip`` and
  ``us_image`` joints (for ROS/MoveIt), and, for a result that corrects the robot, the corrected
  joint origins (the robot given is the software robot, corrected exactly once). The URDF frame
  ``us_image`` is rigid; the pixel spacing stays in the result file (and in the PLUS/Slicer image
  transforms below).
- **3D Slicer / ITK** ``.tfm``: ``#Insight Transform File V1.0`` with an ``AffineTransform_double_3_3``.
  ITK files store the *resampling* transform (Slicer's "from parent") in LPS; Slicer converts to
  RAS and shows the inverse as "to parent". So for a to-parent matrix ``M`` (RAS, mm) the file
  holds ``F M⁻¹ F`` with ``F = diag(-1, -1, 1)``, and Slicer displays ``M`` again.
- **PLUS** ``CoordinateDefinitions``: ``<Transform From="Image" To="Probe" Matrix="…"/>`` in PLUS's
  convention (``From A To B`` maps A into B; millimetres; ``Image`` in pixels, so the matrix
  carries the pixel spacing), plus ``Probe→LeftFlange`` and ``NeedleTip→RightFlange``.
- **ROS** static transforms (YAML): parent, child, translation (m), rotation (x, y, z, w), one entry
  per calibrated joint, with the ``static_transform_publisher`` command line for each.
"""

from __future__ import annotations

import io
import os
import re
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.image_to_probe import ImageCalibration
from brachycal.errors import InputError
from brachycal.files import OutputSet, atomic_open, output_set
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, to_position_quaternion

if TYPE_CHECKING:
    from brachycal.model.description import Rig

LPS = np.diag([-1.0, -1.0, 1.0, 1.0])


def flange_labels(rig: Rig) -> tuple[str, str]:
    """``(needle flange, probe flange)`` names in PLUS and Slicer files: ``RightFlange``/``LeftFlange``
    when each flange link names its side (a ``right``/``left`` word in the link name, the two sides
    different: the SDA10F's ``arm_right_link_tool0``, Baxter's ``right_hand_link``, the UR5 cell's
    ``right_tool0``), else ``NeedleFlange``/``ProbeFlange``."""

    def side(link: str) -> str | None:
        words = set(re.split(r"[^a-z]+", link.lower()))
        sides = [s for s in ("left", "right") if s in words]
        return sides[0].capitalize() if len(sides) == 1 else None

    needle, probe = side(rig.needle_flange), side(rig.probe_flange)
    if needle is None or probe is None or needle == probe:
        return "NeedleFlange", "ProbeFlange"
    return f"{needle}Flange", f"{probe}Flange"


def export_files(rig: Rig) -> tuple[str, ...]:
    """The files :func:`write_exports` writes into its folder for a robot with this rig, in order:
    the calibrated URDF (``<name>_calibrated.urdf``), the three ``.tfm`` files, the PLUS and ROS files."""
    needle, probe = flange_labels(rig)
    return (
        f"{rig.name}_calibrated.urdf",
        "ImageToProbe.tfm",
        f"ProbeTo{probe}.tfm",
        f"NeedleTipTo{needle}.tfm",
        "PlusCoordinateDefinitions.xml",
        "static_transforms.yaml",
    )


#: :func:`export_files` of the bundled SDA10F (the default robot).
EXPORT_FILES = (
    "sda10f_calibrated.urdf",
    "ImageToProbe.tfm",
    "ProbeToLeftFlange.tfm",
    "NeedleTipToRightFlange.tfm",
    "PlusCoordinateDefinitions.xml",
    "static_transforms.yaml",
)


def calibrated_robot(robot: Robot, T_ER_Ntip: ArrayLike, T_EL_Ptip: ArrayLike, image: ImageCalibration) -> Robot:
    """The model with the calibrated tool and image frames."""
    out = robot.with_tool_transform(NEEDLE_TIP, T_ER_Ntip).with_tool_transform(PROBE_TIP, T_EL_Ptip)
    return out.with_tool_transform(US_IMAGE, image.T_Ptip_I)


def image_to_probe_mm(image: ImageCalibration) -> FloatArray:
    """``(4, 4)`` pixel → probe-tip millimetres: ``T_Ptip_I`` with the pixel spacing in its columns."""
    M = image.T_Ptip_I @ np.diag([image.spacing_m[0], image.spacing_m[1], 1.0, 1.0])
    M = M.copy()
    M[:3, :] *= 1e3
    M[3] = [0.0, 0.0, 0.0, 1.0]
    return M


def _mm(T: ArrayLike) -> FloatArray:
    T = np.array(T, dtype=float)
    T[:3, 3] *= 1e3
    return T


def write_itk_transform(M_to_parent: ArrayLike, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write a Slicer "to parent" matrix ``(4, 4)`` (RAS, mm) as an ITK ``.tfm`` file."""
    M = np.asarray(M_to_parent, dtype=float)
    stored = LPS @ np.linalg.inv(M) @ LPS
    numbers = " ".join(repr(float(v)) for v in [*stored[:3, :3].ravel(), *stored[:3, 3]])
    with atomic_open(path, force=force) as f:
        f.write("#Insight Transform File V1.0\n#Transform 0\nTransform: AffineTransform_double_3_3\n")
        f.write(f"Parameters: {numbers}\nFixedParameters: 0 0 0\n")
    return Path(path)


def read_itk_transform(path: str | os.PathLike[str]) -> FloatArray:
    """The "to parent" matrix (RAS, mm) Slicer shows for an ITK ``.tfm`` affine file."""
    path = Path(path)
    fields = {}
    for line in path.read_text().splitlines():
        key, sep, value = line.partition(":")
        if sep and not line.startswith("#"):
            fields[key.strip()] = value.strip()
    if not fields.get("Transform", "").startswith(("AffineTransform_double_3_3", "AffineTransform_float_3_3")):
        raise InputError(f"not a 3D affine ITK transform ({fields.get('Transform')!r})", file=path)
    p = np.array(fields["Parameters"].split(), dtype=float)
    c = np.array(fields.get("FixedParameters", "0 0 0").split(), dtype=float)
    A, t = p[:9].reshape(3, 3), p[9:12]
    stored = make_transform(A, t + c - A @ c)  # ITK: y = A (x − c) + c + t
    # float64 in, float64 out: NumPy's stubs widen linalg results to floating[Any].
    return cast(FloatArray, np.linalg.inv(LPS @ stored @ LPS))


def _matrix_text(M: FloatArray) -> str:
    return "\n        ".join(" ".join(f"{v:.9g}" for v in row) for row in M)


def plus_coordinate_definitions(
    T_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    image: ImageCalibration,
    labels: tuple[str, str] = ("RightFlange", "LeftFlange"),
) -> str:
    """A PLUS ``<CoordinateDefinitions>`` element (text) with the calibrated transforms.

    ``labels``: the needle and probe flanges' PLUS names (:func:`flange_labels`; default the SDA10F's).
    """
    date = datetime.now(UTC).strftime("%Y.%m.%d %H:%M:%S")
    needle, probe = labels
    items = [
        ("Image", "Probe", image_to_probe_mm(image)),
        ("Probe", probe, _mm(T_EL_Ptip)),
        ("NeedleTip", needle, _mm(T_ER_Ntip)),
    ]
    body = "\n".join(
        f'  <Transform From="{a}" To="{b}"\n    Matrix="\n        {_matrix_text(M)}"\n    Date="{date}" />'
        for a, b, M in items
    )
    header = "<CoordinateDefinitions>\n  <!-- brachycal calibration; millimetres, Image in pixels -->\n"
    return f"{header}{body}\n</CoordinateDefinitions>\n"


def ros_static_transforms(
    T_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    image: ImageCalibration,
    flanges: tuple[str, str] = ("arm_right_link_tool0", "arm_left_link_tool0"),
) -> str:
    """ROS static transforms as YAML (metres, quaternion x, y, z, w) with publisher commands.

    ``flanges``: the needle and probe flange links, the tools' parents (``rig.needle_flange``,
    ``rig.probe_flange``; default the SDA10F's).
    """
    needle_flange, probe_flange = flanges
    lines = [
        "# brachycal calibration: static transforms (metres; quaternion x, y, z, w).",
        "# The image's pixel spacing (not a transform) is given as us_image_spacing_m.",
        f"us_image_spacing_m: [{image.spacing_m[0]!r}, {image.spacing_m[1]!r}]",
        "transforms:",
    ]
    for parent, child, T in (
        (needle_flange, NEEDLE_TIP, T_ER_Ntip),
        (probe_flange, PROBE_TIP, T_EL_Ptip),
        (PROBE_TIP, US_IMAGE, image.T_Ptip_I),
    ):
        p, q = to_position_quaternion(np.asarray(T, dtype=float))
        lines += [
            f"  - parent: {parent}",
            f"    child: {child}",
            f"    translation: [{', '.join(repr(float(v)) for v in p)}]",
            f"    rotation: [{', '.join(repr(float(v)) for v in q)}]",
            f"    # ros2 run tf2_ros static_transform_publisher --x {p[0]:.9f} --y {p[1]:.9f} --z {p[2]:.9f} "
            f"--qx {q[0]:.12f} --qy {q[1]:.12f} --qz {q[2]:.12f} --qw {q[3]:.12f} "
            f"--frame-id {parent} --child-frame-id {child}",
        ]
    return "\n".join(lines) + "\n"


def read_ros_static_transforms(text: str) -> dict[tuple[str, str], FloatArray]:
    """``(parent, child)`` → ``T_parent_child (4, 4)`` from :func:`ros_static_transforms` YAML."""
    from ruamel.yaml import YAML
    from scipy.spatial.transform import Rotation

    data = YAML(typ="safe").load(io.StringIO(text))
    out = {}
    for item in data["transforms"]:
        R = Rotation.from_quat(item["rotation"]).as_matrix()
        out[item["parent"], item["child"]] = make_transform(R, item["translation"])
    return out


def write_exports(
    robot: Robot,
    T_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    image: ImageCalibration,
    folder: str | os.PathLike[str],
    *,
    force: bool = False,
    outputs: OutputSet | None = None,
) -> list[Path]:
    """Write every export (:func:`export_files` of ``robot.rig``) into ``folder`` (created if
    needed), all or nothing.

    ``robot`` is the model to write: for a result that corrects the robot, the corrected one
    (:meth:`~brachycal.calibration.StoredCalibration.software_robot`); only its tool joints are
    replaced here. With ``outputs`` (a command's :class:`~brachycal.files.OutputSet`) the files join
    that set and are committed with it; without, they are committed together on return. Returns the
    files' final paths.
    """
    folder = Path(folder)
    rig = robot.rig
    names = export_files(rig)
    urdf, image_tfm, probe_tfm, needle_tfm, plus, ros = names
    labels = flange_labels(rig)
    with output_set(outputs, force=force) as out:
        staged = {name: out.path(folder / name, make_parents=True) for name in names}
        calibrated_robot(robot, T_ER_Ntip, T_EL_Ptip, image).write_urdf(staged[urdf], force=force)
        for name, M in (
            (image_tfm, image_to_probe_mm(image)),
            (probe_tfm, _mm(T_EL_Ptip)),
            (needle_tfm, _mm(T_ER_Ntip)),
        ):
            write_itk_transform(M, staged[name], force=force)
        for name, text in (
            (plus, plus_coordinate_definitions(T_ER_Ntip, T_EL_Ptip, image, labels)),
            (ros, ros_static_transforms(T_ER_Ntip, T_EL_Ptip, image, (rig.needle_flange, rig.probe_flange))),
        ):
            with atomic_open(staged[name], force=force) as f:
                f.write(text)
    return [folder / name for name in names]
