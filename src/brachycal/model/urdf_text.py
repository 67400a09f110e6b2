"""Reading and editing URDF text: tool joints, mesh paths and the record of what an export carries.

The URDF text is the single source of truth of a :class:`~brachycal.model.robot.Robot`; a
calibrated robot is the same text with new ``<origin>`` values on the tool frames' fixed joints.
Comments (provenance, the placeholder warning) survive the edit.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from brachycal.errors import InputError
from brachycal.se3 import FloatArray, from_xyz_rpy, to_xyz_rpy


def parse(urdf_xml: str, source: str) -> ET.Element:
    """Parse URDF text, keeping comments. Raises :class:`InputError` naming ``source``."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        root = ET.fromstring(urdf_xml, parser=parser)
    except ET.ParseError as exc:
        raise InputError(f"not valid XML ({exc})", file=source) from None
    if root.tag != "robot":
        raise InputError(f"root element is <{root.tag}>, expected <robot>", file=source)
    return root


def kinematic_joints(root: ET.Element) -> list[ET.Element]:
    """The ``<joint>`` elements that are direct children of ``<robot>``.

    Only these are the kinematic tree's joints: a ``<transmission>`` (and a ``<gazebo>`` plug-in)
    holds ``<joint name=...>`` elements of its own, which name a joint without defining it.
    """
    return root.findall("joint")


def kinematic_links(root: ET.Element) -> list[ET.Element]:
    """The ``<link>`` elements that are direct children of ``<robot>``."""
    return root.findall("link")


def _fixed_joint_to(root: ET.Element, child: str, source: str) -> ET.Element:
    for joint in kinematic_joints(root):
        node = joint.find("child")
        if node is not None and node.get("link") == child:
            if joint.get("type") != "fixed":
                raise InputError(f"frame {child!r} hangs on a moving joint", file=source)
            return joint
    raise InputError(f"no fixed joint ends at frame {child!r}", file=source)


def _read_origin(joint: ET.Element) -> FloatArray:
    origin = joint.find("origin")
    xyz = [0.0, 0.0, 0.0] if origin is None else [float(v) for v in origin.get("xyz", "0 0 0").split()]
    rpy = [0.0, 0.0, 0.0] if origin is None else [float(v) for v in origin.get("rpy", "0 0 0").split()]
    return from_xyz_rpy(xyz, rpy)


def _write_origin(joint: ET.Element, T: FloatArray) -> None:
    xyz, rpy = to_xyz_rpy(np.asarray(T, dtype=float))
    origin = joint.find("origin")
    if origin is None:
        origin = ET.SubElement(joint, "origin")
    origin.set("xyz", " ".join(repr(float(v)) for v in xyz))
    origin.set("rpy", " ".join(repr(float(v)) for v in rpy))


def fixed_joint_transform(root: ET.Element, child: str, source: str) -> tuple[str, FloatArray]:
    """``(parent link, T_parent_child (4, 4))`` of the fixed joint whose child is ``child``.

    Raises:
        InputError: naming ``source``, when no fixed joint ends at ``child`` or that joint has no
            ``<parent link="...">`` (a URDF that Pinocchio would refuse, but this text may not
            have been through it).
    """
    joint = _fixed_joint_to(root, child, source)
    parent = joint.find("parent")
    link = None if parent is None else parent.get("link")
    if not link:
        raise InputError(
            f"the fixed joint {joint.get('name')!r} ending at frame {child!r} has no parent link", file=source
        )
    return link, _read_origin(joint)


def set_fixed_joint_transform(root: ET.Element, child: str, T_parent_child: FloatArray, source: str) -> None:
    """Replace the ``<origin>`` of the fixed joint ending at ``child`` (in place)."""
    _write_origin(_fixed_joint_to(root, child, source), T_parent_child)


def _joint_named(root: ET.Element, name: str, source: str) -> ET.Element:
    found = [joint for joint in kinematic_joints(root) if joint.get("name") == name]
    if not found:
        raise InputError(f"no joint {name!r}", file=source)
    if len(found) > 1:
        raise InputError(f"{len(found)} joints are named {name!r}", file=source)
    return found[0]


def joint_origin(root: ET.Element, name: str, source: str) -> FloatArray:
    """``T_parent_joint (4, 4)`` of the ``<origin>`` of joint ``name`` (any type)."""
    return _read_origin(_joint_named(root, name, source))


def set_joint_origin(root: ET.Element, name: str, T: FloatArray, source: str) -> None:
    """Replace the ``<origin>`` of joint ``name`` (any type), in place."""
    _write_origin(_joint_named(root, name, source), T)


def rebase_mesh_paths(root: ET.Element, from_dir: Path, to_dir: Path) -> None:
    """Rewrite relative mesh paths (and MuJoCo's ``meshdir``), resolved against ``from_dir``,
    relative to ``to_dir``."""
    targets = [(mesh, "filename") for mesh in root.iter("mesh")]
    targets += [(compiler, "meshdir") for compiler in root.iter("compiler") if compiler.get("meshdir")]
    for element, attribute in targets:
        path = element.get(attribute, "")
        if "://" in path or os.path.isabs(path):
            continue
        element.set(attribute, os.path.relpath((from_dir / path).resolve(), to_dir.resolve()))


def bundle_meshes(root: ET.Element, base_dir: Path, uri_prefix: str, source: str) -> dict[str, Path]:
    """Point every mesh of the URDF at a copy below ``uri_prefix`` (in place); returns
    ``{path of the copy below the prefix: file to copy}``.

    Relative and absolute mesh paths (resolved against ``base_dir``) are bundled; each copy keeps
    its path below the deepest folder common to all the meshes, so two meshes of the same name in
    different folders (Baxter's ``upper_shoulder/``, ``lower_elbow/``...) stay apart, and a mesh
    used twice (the UR5 cell's two arms) is copied once. MuJoCo's ``<compiler meshdir>`` is pointed
    at the prefix. ``package://`` and other URIs are left as they are (nothing to copy from here).

    Raises:
        InputError: a mesh the URDF names is not a readable file (naming ``source``).
    """
    elements: list[tuple[ET.Element, Path]] = []
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        if "://" in name:
            continue
        path = (base_dir / name).resolve()
        if not path.is_file():
            raise InputError(f"mesh {name} is not a file (looked for {path})", file=source)
        elements.append((mesh, path))
    if not elements:
        return {}
    files = sorted({path for _, path in elements})
    common = Path(os.path.commonpath([str(f.parent) for f in files]))
    copies = {path: path.relative_to(common).as_posix() for path in files}
    for mesh, path in elements:
        mesh.set("filename", f"{uri_prefix}/{copies[path]}")
    for compiler in root.iter("compiler"):
        if compiler.get("meshdir"):
            compiler.set("meshdir", uri_prefix)
    return {relative: path for path, relative in copies.items()}


#: The element a URDF written by ``brachycal export`` carries at the top of ``<robot>``: which
#: result it was written from and which of that result's corrections its joints hold. URDF readers
#: (urdfdom/ROS, Pinocchio, yourdfpy, MuJoCo) ignore elements they do not know.
EXPORT_RECORD = "brachycal_export"


def export_records(root: ET.Element) -> list[dict[str, str]]:
    """The attributes of each ``<brachycal_export>`` element of the URDF, in file order (empty: none)."""
    return [dict(element.attrib) for element in root.findall(EXPORT_RECORD)]


def set_export_record(root: ET.Element, record: dict[str, str]) -> None:
    """Add ``<brachycal_export>`` with ``record``'s attributes (in place), replacing a record of the
    same ``result_sha256``; records of other results stay (their corrections are still in the joints)."""
    for element in root.findall(EXPORT_RECORD):
        if element.get("result_sha256") == record.get("result_sha256"):
            root.remove(element)
    children = list(root)
    position = max((k + 1 for k, child in enumerate(children) if child.tag == EXPORT_RECORD), default=0)
    element = ET.Element(EXPORT_RECORD, {k: str(v) for k, v in record.items()})
    element.tail = "\n  "
    root.insert(position, element)


def to_text(root: ET.Element) -> str:
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
