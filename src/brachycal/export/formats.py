"""Writers (and readers, for round trips) of the formats a calibration is used in.

Design: ``docs/design/files.md``, "Export formats".
"""

from __future__ import annotations

import io
import os
import re
import shutil
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.result import Calibration, ImageCalibration, calibration_args
from brachycal.errors import InputError, OutputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, MAX_MESH_BYTES, open_input, read_input_text
from brachycal.io import OutputSet, atomic_open, output_set
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, to_position_quaternion

if TYPE_CHECKING:
    from brachycal.calibration.phantom.stepper_probe import StepperImageFile
    from brachycal.model.rig import Rig

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


def image_to_probe_mm(image: ImageCalibration) -> FloatArray:
    """``(4, 4)`` pixel → probe-tip millimetres, as PLUS's fCal writes ``ImageToProbe``.

    Columns 1 and 2 are ``T_Ptip_I``'s x and y axes times the pixel spacing (mm per pixel), the
    last column the image origin in mm. The third column is the image normal ``x × y`` scaled by
    the mean of the first two columns' lengths (the mean pixel spacing, mm): PLUS completes its
    projection matrix so ("Make the z vector have about the same length as x and y"; PlusLib
    ``src/PlusCalibration/vtkProbeCalibrationAlgo/vtkPlusProbeCalibrationAlgo.cxx``,
    ``ComputeImageToProbeTransformByLinearLeastSquaresMethod``). A 2D image's pixels have z = 0, so
    this column changes no pixel's position (3D Slicer applies the matrix to pixel indices with
    z = 0); it only sets the slice thickness direction of a volume, and keeps the matrix invertible.
    """
    spacing_mm = 1e3 * np.asarray(image.spacing_m, dtype=float)
    M = np.eye(4)
    M[:3, 0] = image.T_Ptip_I[:3, 0] * spacing_mm[0]
    M[:3, 1] = image.T_Ptip_I[:3, 1] * spacing_mm[1]
    normal = np.cross(M[:3, 0], M[:3, 1])
    M[:3, 2] = normal / np.linalg.norm(normal) * (np.linalg.norm(M[:3, 0]) + np.linalg.norm(M[:3, 1])) / 2
    M[:3, 3] = image.T_Ptip_I[:3, 3] * 1e3
    return M


def _one(function: str, rest: tuple[Any, ...], default: Any) -> Any:
    """The one optional positional argument left in ``rest`` (``default`` if none)."""
    if len(rest) > 1:
        raise TypeError(f"{function}() takes at most one more positional argument")
    return rest[0] if rest else default


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
    for line in read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES).splitlines():
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


def plus_coordinate_definitions(calibration: Calibration, *args: Any) -> str:
    """A PLUS ``<CoordinateDefinitions>`` element (text) with ``calibration``'s transforms.

    ``plus_coordinate_definitions(calibration, labels=("RightFlange", "LeftFlange"))``: ``labels``
    are the needle and probe flanges' PLUS names (:func:`flange_labels`; default the SDA10F's). The
    loose form ``(T_ER_Ntip, T_EL_Ptip, image, labels)`` works for one release (deprecated).
    """
    calibration, rest = calibration_args("plus_coordinate_definitions", calibration, args)
    labels: tuple[str, str] = _one("plus_coordinate_definitions", rest, ("RightFlange", "LeftFlange"))
    T_ER_Ntip, T_EL_Ptip, image = calibration.T_ER_Ntip, calibration.T_EL_Ptip, calibration.image
    needle, probe = labels
    items = [
        ("Image", "Probe", image_to_probe_mm(image)),
        ("Probe", probe, _mm(T_EL_Ptip)),
        ("NeedleTip", needle, _mm(T_ER_Ntip)),
    ]
    return coordinate_definitions_text(items)


def coordinate_definitions_text(items: Sequence[tuple[str, str, FloatArray]], comment: str = "") -> str:
    """A PLUS ``<CoordinateDefinitions>`` element (text): one ``Transform`` per ``(From, To, matrix in mm)``."""
    date = datetime.now(UTC).strftime("%Y.%m.%d %H:%M:%S")
    body = "\n".join(
        f'  <Transform From="{a}" To="{b}"\n    Matrix="\n        {_matrix_text(M)}"\n    Date="{date}" />'
        for a, b, M in items
    )
    header = f"<CoordinateDefinitions>\n  <!-- brachycal calibration; millimetres, Image in pixels{comment} -->\n"
    return f"{header}{body}\n</CoordinateDefinitions>\n"


def _yaml_float(representer, value: float):  # ruamel's representer type is not exported
    """A float as YAML 1.1 and 1.2 both read it: always with a dot (``1.0e-05``, not ``1e-05``,
    which PyYAML and ROS 1's rosparam would read as a string)."""
    text = repr(float(value))
    if "e" in text and "." not in text:
        text = text.replace("e", ".0e")
    return representer.represent_scalar("tag:yaml.org,2002:float", text)


def _yaml_text(data: object, header: str) -> str:
    from ruamel.yaml import YAML  # lazy: start-up (ruamel)

    yaml = YAML(typ="safe", pure=True)
    yaml.default_flow_style = None  # lists of numbers on one line, mappings in blocks
    yaml.width = 4096  # a command line stays on one line
    yaml.sort_base_mapping_type_on_output = False  # type: ignore[assignment]  # keys in the order written
    yaml.representer.add_representer(float, _yaml_float)
    buffer = io.StringIO()
    yaml.dump(data, buffer)
    return header + buffer.getvalue()


def static_transforms(
    calibration: Calibration,
    flanges: tuple[str, str] = ("arm_right_link_tool0", "arm_left_link_tool0"),
) -> list[tuple[str, str, FloatArray, FloatArray]]:
    """``[(parent, child, translation (3,) m, quaternion (x, y, z, w))]`` of the calibrated joints:
    needle tip on its flange, probe tip on its flange, image on the probe tip."""
    needle_flange, probe_flange = flanges
    T_ER_Ntip, T_EL_Ptip, image = calibration.T_ER_Ntip, calibration.T_EL_Ptip, calibration.image
    out = []
    for parent, child, T in (
        (needle_flange, NEEDLE_TIP, T_ER_Ntip),
        (probe_flange, PROBE_TIP, T_EL_Ptip),
        (PROBE_TIP, US_IMAGE, image.T_Ptip_I),
    ):
        p, q = to_position_quaternion(np.asarray(T, dtype=float))
        out.append((parent, child, p, q))
    return out


def _numbers(values: ArrayLike) -> list[str]:
    return [repr(float(v)) for v in np.asarray(values, dtype=float)]


def ros2_arguments(parent: str, child: str, p: ArrayLike, q: ArrayLike) -> list[str]:
    """``static_transform_publisher``'s arguments in ROS 2's named form (Humble and later)."""
    x, y, z = _numbers(p)
    qx, qy, qz, qw = _numbers(q)
    return [
        *("--x", x, "--y", y, "--z", z, "--qx", qx, "--qy", qy, "--qz", qz, "--qw", qw),
        *("--frame-id", parent, "--child-frame-id", child),
    ]


def ros1_arguments(parent: str, child: str, p: ArrayLike, q: ArrayLike) -> list[str]:
    """``static_transform_publisher``'s arguments in ROS 1's order: x y z qx qy qz qw frame_id child_frame_id."""
    return [*_numbers(p), *_numbers(q), parent, child]


def ros_static_transforms(calibration: Calibration, *args: Any) -> str:
    """ROS static transforms as YAML (metres, quaternion x, y, z, w) with publisher commands.

    Per transform: ``parent``, ``child``, ``translation``, ``rotation``, and the
    ``static_transform_publisher`` command for ROS 2 (``ros2``, named arguments) and ROS 1
    (``ros1``, positional x y z qx qy qz qw frame_id child_frame_id). ``flanges``: the needle and
    probe flange links, the tools' parents (``rig.needle_flange``, ``rig.probe_flange``; default
    the SDA10F's). Numbers are written in full (``repr``) precision.

    ``ros_static_transforms(calibration, flanges=...)``; the loose form ``(T_ER_Ntip, T_EL_Ptip,
    image, flanges)`` works for one release (deprecated).
    """
    calibration, rest = calibration_args("ros_static_transforms", calibration, args)
    flanges: tuple[str, str] = _one("ros_static_transforms", rest, ("arm_right_link_tool0", "arm_left_link_tool0"))
    transforms = []
    for parent, child, p, q in static_transforms(calibration, flanges):
        transforms.append(
            {
                "parent": parent,
                "child": child,
                "translation": [float(v) for v in p],
                "rotation": [float(v) for v in q],
                "ros2": "ros2 run tf2_ros static_transform_publisher " + " ".join(ros2_arguments(parent, child, p, q)),
                "ros1": "rosrun tf2_ros static_transform_publisher " + " ".join(ros1_arguments(parent, child, p, q)),
            }
        )
    header = (
        "# brachycal calibration: static transforms (metres; quaternion x, y, z, w).\n"
        "# The image's pixel spacing (not a transform) is given as us_image_spacing_m.\n"
    )
    data = {"us_image_spacing_m": [float(v) for v in calibration.spacing_m], "transforms": transforms}
    return _yaml_text(data, header)


def read_ros_static_transforms(text: str) -> dict[tuple[str, str], FloatArray]:
    """``(parent, child)`` → ``T_parent_child (4, 4)`` from :func:`ros_static_transforms` YAML."""
    from ruamel.yaml import YAML  # lazy: start-up (ruamel)
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    data = YAML(typ="safe").load(io.StringIO(text))
    out = {}
    for item in data["transforms"]:
        R = Rotation.from_quat(item["rotation"]).as_matrix()
        out[item["parent"], item["child"]] = make_transform(R, item["translation"])
    return out


def _write_urdf_folder(
    robot: Robot,
    staged_urdf: Path,
    mesh_folder: Path,
    mesh_prefix: str,
    record: Mapping[str, str] | None,
    out: OutputSet,
) -> list[Path]:
    """Write ``robot``'s URDF to ``staged_urdf`` with its meshes copied below ``mesh_folder`` (each
    claimed in ``out``); returns the meshes' final paths."""
    text, copies = robot.bundled_urdf(mesh_prefix, record)
    with atomic_open(staged_urdf, force=out.force) as f:
        f.write(text)
    written = []
    for relative, source in copies.items():
        destination = mesh_folder / relative
        staged = out.path(destination, make_parents=True)
        try:
            reader = open_input(source, max_bytes=MAX_MESH_BYTES)
        except InputError as exc:
            raise InputError(f"cannot copy mesh {source} ({exc.problem})", file=robot.source) from None
        with reader:
            try:
                with open(staged, "wb") as writer:
                    shutil.copyfileobj(reader, writer)
            except OSError as exc:  # writing: reading a checked regular file does not fail this way
                raise OutputError(f"cannot write ({exc.strerror or exc})", file=destination) from None
        written.append(destination)
    return written


def write_exports(
    robot: Robot,
    calibration: Calibration,
    *args: Any,
    force: bool = False,
    outputs: OutputSet | None = None,
    record: Mapping[str, str] | None = None,
) -> list[Path]:
    """Write every export (:func:`export_files` of ``robot.rig``) into ``folder`` (created if
    needed), with a ``meshes/`` folder holding a copy of each mesh the URDF names, all or nothing.

    ``robot`` is the model to write: for a result that corrects the robot, the corrected one
    (:meth:`~brachycal.calibration.ResultFile.software_robot`); only its tool joints are
    replaced here. ``record``: the ``<brachycal_export>`` attributes the URDF carries
    (:meth:`~brachycal.calibration.ResultFile.export_record`). With ``outputs`` (a command's
    :class:`~brachycal.io.OutputSet`) the files join that set and are committed with it; without,
    they are committed together on return. Returns the files' final paths (the meshes last).

    ``write_exports(robot, calibration, folder, ...)``; the loose form ``(robot, T_ER_Ntip,
    T_EL_Ptip, image, folder, ...)`` works for one release (deprecated).
    """
    calibration, rest = calibration_args("write_exports", calibration, args)
    if len(rest) != 1:
        raise TypeError("write_exports() takes (robot, calibration, folder)")
    folder = Path(rest[0])
    T_ER_Ntip, T_EL_Ptip, image = calibration.T_ER_Ntip, calibration.T_EL_Ptip, calibration.image
    rig = robot.rig
    names = export_files(rig)
    urdf, image_tfm, probe_tfm, needle_tfm, plus, ros = names
    labels = flange_labels(rig)
    with output_set(outputs, force=force) as out:
        staged = {name: out.path(folder / name, make_parents=True) for name in names}
        calibrated = calibration.robot(robot)
        meshes = _write_urdf_folder(calibrated, staged[urdf], folder / "meshes", "meshes", record, out)
        for name, M in (
            (image_tfm, image_to_probe_mm(image)),
            (probe_tfm, _mm(T_EL_Ptip)),
            (needle_tfm, _mm(T_ER_Ntip)),
        ):
            write_itk_transform(M, staged[name], force=force)
        for name, text in (
            (plus, plus_coordinate_definitions(calibration, labels)),
            (ros, ros_static_transforms(calibration, (rig.needle_flange, rig.probe_flange))),
        ):
            with atomic_open(staged[name], force=force) as f:
                f.write(text)
    return [*(folder / name for name in names), *meshes]


#: ROS package names (REP 144): lowercase letters, digits and underscores, starting with a letter.
ROS_PACKAGE_NAME = re.compile(r"[a-z][a-z0-9_]*")


def check_ros_package_name(name: str) -> str:
    """``name`` if it is a ROS package name (REP 144), else a one-line refusal naming ``--ros-package``.

    Raises:
        InputError: not lowercase letters, digits and underscores starting with a letter, or a
            double or trailing underscore (which REP 144 does not allow).
    """
    if not ROS_PACKAGE_NAME.fullmatch(name) or "__" in name or name.endswith("_"):
        raise InputError(
            f"--ros-package {name!r} is not a ROS package name: lowercase letters, digits and single "
            "underscores, starting with a letter (REP 144), e.g. sda10f_calibration"
        )
    return name


def ros_package_files(rig: Rig, name: str) -> tuple[str, ...]:
    """The files :func:`write_ros_package` writes below ``DIR/name/``, besides the meshes."""
    return (
        "package.xml",
        "CMakeLists.txt",
        f"urdf/{rig.name}_calibrated.urdf",
        f"launch/{name}.launch.py",
        "config/static_transforms.yaml",
    )


_PACKAGE_XML = """<?xml version="1.0"?>
<?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>Calibrated {robot} description written by brachycal: the URDF with the calibrated needle,
    probe and ultrasound image frames, its meshes, and a launch file that publishes them.</description>
  <!-- brachycal cannot know who maintains this calibration: edit the maintainer and the license
       (the meshes keep the license of the robot description they were copied from). -->
  <maintainer email="maintainer@example.com">Maintainer of this calibration</maintainer>
  <license>TODO</license>

  <buildtool_depend>ament_cmake</buildtool_depend>

  <exec_depend>launch</exec_depend>
  <exec_depend>launch_ros</exec_depend>
  <exec_depend>robot_state_publisher</exec_depend>
  <exec_depend>tf2_ros</exec_depend>

  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""

_CMAKE_LISTS = """cmake_minimum_required(VERSION 3.8)
project({name} NONE)

find_package(ament_cmake REQUIRED)

install(DIRECTORY {folders} DESTINATION share/${{PROJECT_NAME}})

ament_package()
"""

_LAUNCH = '''"""Calibrated {robot} (brachycal): the robot and its calibrated tool and image frames on /tf.

publish_robot:=true (default): robot_state_publisher with the calibrated URDF, which carries the
calibrated needle_tip, probe_tip and us_image frames as fixed joints (and any corrected joint
origins). publish_robot:=false: only the calibrated transforms, one static_transform_publisher
each, for a set-up whose robot description another package publishes.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    share = get_package_share_directory("{name}")
    with open(os.path.join(share, "urdf", "{urdf}")) as f:
        robot_description = f.read()
    publish_robot = LaunchConfiguration("publish_robot")
    return LaunchDescription([
        DeclareLaunchArgument("publish_robot", default_value="true"),
        Node(
            package="robot_state_publisher",
            executable="robot_state_publisher",
            parameters=[{{"robot_description": robot_description}}],
            condition=IfCondition(publish_robot),
        ),
{nodes}    ])
'''

_LAUNCH_NODE = """        Node(
            package="tf2_ros",
            executable="static_transform_publisher",
            name="{node}",
            arguments={arguments},
            condition=UnlessCondition(publish_robot),
        ),
"""


def _launch_file(name: str, rig: Rig, urdf: str, transforms: list[tuple[str, str, FloatArray, FloatArray]]) -> str:
    nodes = "".join(
        _LAUNCH_NODE.format(node=f"{parent}_to_{child}", arguments=repr(ros2_arguments(parent, child, p, q)))
        for parent, child, p, q in transforms
    )
    return _LAUNCH.format(robot=rig.name, name=name, urdf=urdf, nodes=nodes)


def write_ros_package(
    robot: Robot,
    calibration: Calibration,
    *args: Any,
    force: bool = False,
    outputs: OutputSet | None = None,
    record: Mapping[str, str] | None = None,
) -> list[Path]:
    """Write a ROS 2 (ament_cmake) description package ``folder/name/``, all or nothing.

    It holds ``package.xml`` (format 3), ``CMakeLists.txt`` (installs ``urdf/``, ``meshes/``,
    ``launch/``, ``config/`` into the package's share folder), the calibrated URDF with
    ``package://name/meshes/...`` mesh URIs, the meshes it names, ``launch/name.launch.py``
    (robot_state_publisher with the URDF, or with ``publish_robot:=false`` one
    static_transform_publisher per calibrated transform, ROS 2 Humble's named arguments) and
    ``config/static_transforms.yaml`` (:func:`ros_static_transforms`). Other arguments as
    :func:`write_exports`. Returns the files' final paths (the meshes last).

    Raises:
        InputError: ``name`` is not a ROS package name (:func:`check_ros_package_name`).

    ``write_ros_package(robot, calibration, folder, name, ...)``; the loose form ``(robot,
    T_ER_Ntip, T_EL_Ptip, image, folder, name, ...)`` works for one release (deprecated).
    """
    calibration, rest = calibration_args("write_ros_package", calibration, args)
    if len(rest) != 2:
        raise TypeError("write_ros_package() takes (robot, calibration, folder, name)")
    folder, name = rest
    name = check_ros_package_name(name)
    package = Path(folder) / name
    rig = robot.rig
    files = ros_package_files(rig, name)
    xml, cmake, urdf, launch, config = files
    flanges = (rig.needle_flange, rig.probe_flange)
    with output_set(outputs, force=force) as out:
        staged = {file: out.path(package / file, make_parents=True) for file in files}
        calibrated = calibration.robot(robot)
        meshes = _write_urdf_folder(
            calibrated, staged[urdf], package / "meshes", f"package://{name}/meshes", record, out
        )
        folders = " ".join(["urdf", *(["meshes"] if meshes else []), "launch", "config"])
        transforms = static_transforms(calibration, flanges)
        for file, text in (
            (xml, _PACKAGE_XML.format(name=name, robot=rig.name)),
            (cmake, _CMAKE_LISTS.format(name=name, folders=folders)),
            (launch, _launch_file(name, rig, Path(urdf).name, transforms)),
            (config, ros_static_transforms(calibration, flanges)),
        ):
            with atomic_open(staged[file], force=force) as f:
                f.write(text)
    return [*(package / file for file in files), *meshes]


#: The files :func:`write_stepper_exports` writes.
STEPPER_EXPORT_FILES = ("ImageToProbe.tfm", "PhantomToStepperHome.tfm", "PlusCoordinateDefinitions.xml")


def write_stepper_exports(
    result: StepperImageFile, folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None
) -> list[Path]:
    """Write a stepper Image → Probe result's hand-off into ``folder``, all or nothing.

    ``ImageToProbe.tfm`` (pixels → mm, PLUS's form, the chosen model), ``PhantomToStepperHome.tfm``
    (the phantom's registration, the template at home) for 3D Slicer and ITK, and
    ``PlusCoordinateDefinitions.xml`` with both (PLUS's ``Image → Probe`` and ``Phantom → StepperHome``).
    The Image → Probe belongs with poses built along the stepper axes the result records.
    """
    folder = Path(folder)
    image_to_probe = result.image_to_probe.copy()
    image_to_probe[:3, :] *= 1e3  # pixels -> mm: the scaled columns and the translation
    phantom = _mm(result.T_template_phantom)
    a = result.axes.probe_translation
    comment = f"; stepper poses along the probe axis {a[0]:.6g} {a[1]:.6g} 1"
    with output_set(outputs, force=force) as out:
        staged = {name: out.path(folder / name, make_parents=True) for name in STEPPER_EXPORT_FILES}
        write_itk_transform(image_to_probe, staged["ImageToProbe.tfm"], force=force)
        write_itk_transform(phantom, staged["PhantomToStepperHome.tfm"], force=force)
        items = [("Image", "Probe", image_to_probe), ("Phantom", "StepperHome", phantom)]
        with atomic_open(staged["PlusCoordinateDefinitions.xml"], force=force) as f:
            f.write(coordinate_definitions_text(items, comment))
    return [folder / name for name in STEPPER_EXPORT_FILES]
