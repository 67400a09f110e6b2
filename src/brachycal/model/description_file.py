"""Reading a robot description file (``brachycal-robot/1``, ``docs/robots.md``): the TOML's keys
checked one by one, the URDF text built in memory (the tool frames appended as fixed joints, single
arms merged under one base, frozen joints made fixed, ``package://`` mesh paths resolved), and the
:class:`~brachycal.model.rig.Rig` checked against the kinematic model built from that text.

Two steps, so that no kinematic model is built here: :func:`read_description_file` (the TOML and the
URDF text, a :class:`DescriptionFile`), then :func:`rig_of` (its rig, given the Pinocchio model built
from :attr:`DescriptionFile.urdf_xml` with its coordinates and limits).
:func:`~brachycal.model.description.load_description` does both around a
:class:`~brachycal.model.robot.Robot`.
"""

from __future__ import annotations

import importlib.metadata
import math
import os
import re
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import pinocchio as pin

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_bytes, read_input_text
from brachycal.io import bundled
from brachycal.model import urdf_text
from brachycal.model.rig import TOOL_FRAMES, Arm, ArmDescription, Rig, Workspace
from brachycal.se3 import FloatArray, from_xyz_rpy, make_transform
from brachycal.validate import check_finite, check_transform

__all__ = [
    "BUNDLED_ROBOTS",
    "DEFAULT_ROBOT",
    "FORMAT",
    "MAX_OFFSET_M",
    "SINGLE_ARM_ROBOTS",
    "DescriptionFile",
    "arms_of",
    "bundled_description_path",
    "example_robot_data_share",
    "read_description_file",
    "rig_of",
]

FORMAT = "brachycal-robot/1"
DEFAULT_ROBOT = "sda10f"
#: Descriptions shipped in ``brachycal/robots/<name>.toml``.
BUNDLED_ROBOTS: tuple[str, ...] = ("sda10f", "baxter", "ur5_pair")
#: Single-arm descriptions shipped likewise (``[[arm]]``; example-robot-data's URDFs): for the
#: commands about any arm (``model``, ``fk``, robot identification), not the dual-arm rig's.
SINGLE_ARM_ROBOTS: tuple[str, ...] = ("panda", "ur5", "ur10")

#: Largest |value| of a mount or tool translation, metres: no tool or robot cell is 10 m across,
#: so a larger value is a unit slip (millimetres typed as metres).
MAX_OFFSET_M = 10.0

# Joint children that only a moving joint has (removed when a joint is frozen).
_MOVING_JOINT_TAGS = ("axis", "limit", "mimic", "dynamics", "calibration", "safety_controller")
_TOP_KEYS = {
    "format",
    "name",
    "summary",
    "urdf",
    "mount",
    "arm",
    "base",
    "package_dirs",
    "remove_links",
    "frozen",
    "collision",
    "needle_arm",
    "probe_arm",
    "shared",
    "controller",
    "tools",
    "workspace",
}


@dataclass(frozen=True)
class DescriptionFile:
    """A description file read and checked up to its kinematics: the URDF text to build the model
    from, and what :func:`rig_of` needs to check the rig against that model.

    Attributes:
        source: the TOML file.
        urdf_xml: the built URDF text (tool frames, mounts, frozen joints applied).
        base_dir: the folder relative mesh paths of ``urdf_xml`` are resolved against.
        name: the description's short name.
        summary: its one line (may be empty).
        base: the root link.
        dual_arm: it names a needle arm and a probe arm (a rig, :func:`rig_of`); else it names
            ``[[arm]]`` tables (:func:`arms_of`).
    """

    source: Path
    urdf_xml: str = field(repr=False)
    base_dir: Path
    name: str
    summary: str
    base: str
    dual_arm: bool
    _reader: _Reader = field(repr=False, compare=False)
    _data: dict[str, Any] = field(repr=False, compare=False)
    _parsed: dict[str, Any] = field(repr=False, compare=False)


def read_description_file(path: Path) -> DescriptionFile:
    """Read the description at ``path`` (already checked to be a readable file of bounded size) up to
    its URDF text.

    Raises:
        InputError: one line naming the file and the key (see
            :func:`~brachycal.model.description.load_description`).
    """
    r = _Reader(path)
    try:
        data = tomllib.loads(read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"not valid TOML ({exc})", file=path) from None
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise r.fail(unknown[0], f"unknown key (allowed: {', '.join(sorted(_TOP_KEYS))})")
    for key in ("format", "name", "base"):
        if key not in data:
            raise r.fail(key, "missing")
    dual_arm = _check_kind(data, r)
    if data["format"] != FORMAT:
        raise r.fail("format", f"must be {FORMAT!r}, got {data['format']!r}")
    name = r.string(data["name"], "name")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_.-]*", name):  # it names files (the exported URDF): no paths
        raise r.fail("name", f"must be letters, digits, '_', '.', '-' starting with a letter, got {name!r}")
    summary = str(data.get("summary", ""))
    base = r.string(data["base"], "base")
    folder = path.parent

    package_dirs = [folder / p for p in r.strings(data.get("package_dirs", []), "package_dirs")]
    try:
        package_dirs.append(example_robot_data_share().parent)  # package://example-robot-data/...
    except InputError:  # not installed: only descriptions that use it need it, and they say so
        pass

    # The URDF: one file, or single arms mounted on one base.
    mounts: dict[str, FloatArray] = {}
    srdf_pairs: set[frozenset[str]] = set()
    if ("urdf" in data) == ("mount" in data):
        raise r.fail("urdf", "give either urdf (one robot) or [[mount]] tables (single arms on one base), not both")
    if "urdf" in data:
        urdf_path = _resolve(r.string(data["urdf"], "urdf"), folder, "urdf", path)
        root = _read_urdf(urdf_path, "urdf", path)
        base_dir = urdf_path.parent
        _resolve_meshes(root, urdf_path, base_dir, package_dirs, path, required=dual_arm)
        actual_root = _root_link(root, path, "urdf")
        if base != actual_root:
            raise r.fail("base", f"must be the URDF's root link {actual_root!r}, got {base!r}")
    else:
        root, base_dir = _mount_arms(data["mount"], base, folder, package_dirs, r, mounts, srdf_pairs, dual_arm)

    remove = r.strings(data.get("remove_links", []), "remove_links")
    _remove_subtrees(root, remove, r)
    frozen_in = data.get("frozen", {})
    if not isinstance(frozen_in, dict):
        raise r.fail("frozen", f"must be a table of joint = value, got {_kind(frozen_in)}")
    frozen = {k: r.numbers([v], f"frozen.{k}", 1)[0] for k, v in frozen_in.items()}
    frozen = _freeze(root, frozen, r)
    _add_mujoco_block(root)

    # Collision pairs to ignore.
    collision = r.table(data, "collision", {"srdf"}, set()) if "collision" in data else {}
    for ref in r.strings(collision.get("srdf", []), "collision.srdf"):
        srdf_pairs |= _srdf_pairs(_resolve(ref, folder, "collision.srdf", path), "", "collision.srdf", path)

    if not dual_arm:
        arms = _read_arms(root, data["arm"], base, r)
        parsed = dict(name=name, summary=summary, base=base, frozen=frozen, arms=arms)
        return DescriptionFile(path, urdf_text.to_text(root), base_dir, name, summary, base, False, r, data, parsed)

    # Tool frames: from the description, or already in the URDF (the bundled SDA10F's).
    arm_keys = {"flange", "joints", "ready_rad"}
    needle_table = r.table(data, "needle_arm", arm_keys, arm_keys)
    probe_table = r.table(data, "probe_arm", arm_keys, arm_keys)
    flanges = {
        "needle_flange": r.string(needle_table["flange"], "needle_arm.flange"),
        "probe_flange": r.string(probe_table["flange"], "probe_arm.flange"),
    }
    links = set(_links(root))
    for which, link in flanges.items():
        key = f"{which.split('_')[0]}_arm.flange"
        if link not in links:
            raise r.fail(key, f"no link {link!r} in the URDF")
    tools = r.table(data, "tools", set(TOOL_FRAMES), set())
    for frame, mount in TOOL_FRAMES.items():
        parent = flanges.get(mount, mount)
        existing = [j for j in _joints(root).values() if _child(j) == frame]
        if frame in tools:
            if existing or frame in links:
                raise r.fail(f"tools.{frame}", f"the URDF already has a frame {frame!r}; keep one of the two")
            table = r.table(tools, frame, {"xyz_m", "rpy_rad", "matrix", "what"}, set())
            T = r.transform(table, f"tools.{frame}")
            _add_fixed_frame(root, frame, parent, T, str(table.get("what", "")))
            links.add(frame)
        elif not existing:
            raise r.fail(f"tools.{frame}", f"missing: the URDF has no frame {frame!r} (mount it on {parent!r})")
        else:
            (tool_joint,) = existing
            if tool_joint.get("type") != "fixed" or _parent(tool_joint) != parent:
                raise r.fail(
                    f"tools.{frame}",
                    f"the URDF's {frame!r} must hang on {parent!r} by a fixed joint, "
                    f"it hangs on {_parent(tool_joint)!r}",
                )

    urdf_xml = urdf_text.to_text(root)
    parsed = dict(
        name=name,
        summary=summary,
        base=base,
        mounts=mounts,
        srdf_pairs=srdf_pairs,
        frozen=frozen,
        flanges=flanges,
        needle_table=needle_table,
        probe_table=probe_table,
    )
    return DescriptionFile(path, urdf_xml, base_dir, name, summary, base, True, r, data, parsed)


#: Keys only a dual-arm description has.
_DUAL_ARM_KEYS = ("needle_arm", "probe_arm", "shared", "controller", "tools", "workspace")


def _check_kind(data: Mapping[str, Any], r: _Reader) -> bool:
    """Whether the description is a dual-arm rig (``[needle_arm]``, ``[probe_arm]``, ``[tools]``,
    ``[workspace]``) rather than ``[[arm]]`` tables; refuses a mix and a missing part."""
    dual = "needle_arm" in data or "probe_arm" in data
    if "arm" in data and dual:
        raise r.fail(
            "arm",
            "give either [[arm]] tables (any arms) or [needle_arm] and [probe_arm] (a dual-arm rig), not both",
        )
    if "arm" in data:
        for key in _DUAL_ARM_KEYS:
            if key in data:
                raise r.fail(
                    key, "belongs to a dual-arm description ([needle_arm] and [probe_arm]), not to [[arm]] tables"
                )
        return False
    if not dual:
        raise r.fail(
            "arm",
            "missing: name the robot's arms ([[arm]] tables), "
            "or its needle arm and probe arm ([needle_arm] and [probe_arm])",
        )
    for key in ("needle_arm", "probe_arm", "tools", "workspace"):
        if key not in data:
            raise r.fail(
                key, "missing (a dual-arm description names the needle arm, the probe arm, the tools and the workspace)"
            )
    return True


_ARM_KEYS = {"name", "base", "flange", "tool"}
_TOOL_KEYS = {"frame", "xyz_m", "rpy_rad", "matrix", "what"}


def _read_arms(root: ET.Element, tables: object, base: str, r: _Reader) -> list[dict[str, Any]]:
    """The ``[[arm]]`` tables checked against the URDF tree (a tool table added as a fixed frame on its
    flange): ``name``, ``base``, ``flange``, ``tool`` (or None) and ``chain``, the moving joints from
    the base link to the flange, root to flange."""
    if not isinstance(tables, list) or not tables or not all(isinstance(t, dict) for t in tables):
        raise r.fail("arm", "must be [[arm]] tables, one per arm")
    arms: list[dict[str, Any]] = []
    for i, table in enumerate(tables):
        key = f"arm[{i}]"
        table = r.table({key: table}, key, _ARM_KEYS, {"name", "flange"})
        name = r.string(table["name"], f"{key}.name")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name):
            raise r.fail(f"{key}.name", f"must be letters, digits and '_' starting with a letter, got {name!r}")
        if any(arm["name"] == name for arm in arms):
            raise r.fail(f"{key}.name", f"arm {name!r} is named twice")
        links = set(_links(root))
        flange = r.string(table["flange"], f"{key}.flange")
        arm_base = r.string(table.get("base", base), f"{key}.base")
        for which, link in (("flange", flange), ("base", arm_base)):
            if link not in links:
                raise r.fail(f"{key}.{which}", f"no link {link!r} in the URDF")
        chain = _path_up(root, flange, arm_base)
        if chain is None:
            raise r.fail(f"{key}.base", f"link {arm_base!r} is not above the flange {flange!r} in the URDF's tree")
        moving = [joint for joint in chain if _joints(root)[joint].get("type") != "fixed"]
        if not moving:
            raise r.fail(f"{key}.flange", f"no joint moves {flange!r} relative to {arm_base!r}")
        tool: str | None = None
        if "tool" in table:
            value = table["tool"]
            if isinstance(value, dict):
                spec = r.table({key: {"tool": value}}, f"{key}.tool", _TOOL_KEYS, {"frame"})
                tool = r.string(spec["frame"], f"{key}.tool.frame")
                if tool in links:
                    raise r.fail(
                        f"{key}.tool.frame", f"the URDF already has a frame {tool!r}: name it (tool = {tool!r})"
                    )
                T = r.transform(spec, f"{key}.tool")
                _add_fixed_frame(root, tool, flange, T, str(spec.get("what", "")))
            else:
                tool = r.string(value, f"{key}.tool")
                if tool not in links:
                    raise r.fail(f"{key}.tool", f"no link {tool!r} in the URDF")
                below = _path_up(root, tool, flange)
                if below is None:
                    raise r.fail(f"{key}.tool", f"frame {tool!r} is not below the flange {flange!r}")
                loose = [joint for joint in below if _joints(root)[joint].get("type") != "fixed"]
                if loose:
                    raise r.fail(
                        f"{key}.tool", f"frame {tool!r} is not rigidly on the flange: joint {loose[0]!r} moves it"
                    )
        arms.append(dict(name=name, base=arm_base, flange=flange, tool=tool, chain=moving))
    return arms


def _path_up(root: ET.Element, link: str, ancestor: str) -> list[str] | None:
    """Names of the joints from ``ancestor`` down to ``link`` (root to link), or None if ``ancestor``
    is not above ``link`` (a link is above itself: no joints)."""
    parent_joint = {_child(joint): joint for joint in _joints(root).values()}
    path: list[str] = []
    while link != ancestor:
        joint = parent_joint.get(link)
        if joint is None:
            return None
        path.append(str(joint.get("name")))
        link = _parent(joint)
    return path[::-1]


def arms_of(file: DescriptionFile, joint_names: tuple[str, ...]) -> tuple[Arm, ...]:
    """The ``[[arm]]`` tables of ``file`` as :class:`~brachycal.model.rig.Arm`, each arm's joints the
    configuration coordinates ``joint_names`` (of the model built from :attr:`DescriptionFile.urdf_xml`)
    on its chain, root to flange. A dual-arm description's arms are its rig's (:attr:`Rig.arms`).

    Raises:
        InputError: naming the file and the key: an arm moved by no coordinate (only mimic joints).
    """
    if file.dual_arm:
        raise ValueError("a dual-arm description's arms are its rig's (Rig.arms)")
    arms = []
    for i, arm in enumerate(file._parsed["arms"]):
        joints = tuple(joint for joint in arm["chain"] if joint in joint_names)
        if not joints:
            raise file._reader.fail(f"arm[{i}].flange", f"no configuration coordinate moves {arm['flange']!r}")
        arms.append(Arm(arm["name"], arm["base"], arm["flange"], arm["tool"], joints))
    return tuple(arms)


def rig_of(
    file: DescriptionFile, model: pin.Model, joint_names: tuple[str, ...], lower: FloatArray, upper: FloatArray
) -> Rig:
    """The rig of ``file``, checked against the kinematic model built from its URDF text: ``model``
    with its configuration coordinates ``joint_names`` and their limits ``lower``/``upper``
    (``(nq,)``, radians or metres).

    Raises:
        InputError: naming the file and the key: a joint in no arm or in the wrong one, a ready
            stance of the wrong length or outside the limits, a bad controller order, a bad workspace.
    """
    if not file.dual_arm:
        raise ValueError("an [[arm]] description has no rig (arms_of gives its arms)")
    r, data, path = file._reader, file._data, file.source
    p = file._parsed
    name, summary, base = p["name"], p["summary"], p["base"]
    mounts, srdf_pairs, frozen = p["mounts"], p["srdf_pairs"], p["frozen"]
    flanges, needle_table, probe_table = p["flanges"], p["needle_table"], p["probe_table"]
    coordinates = set(joint_names)
    needle_chain, probe_chain = (
        set(_chain(model, flanges["needle_flange"])),
        set(_chain(model, flanges["probe_flange"])),
    )

    def arm(table: dict[str, Any], key: str) -> ArmDescription:
        joints = r.strings(table["joints"], f"{key}.joints")
        ready = r.numbers(table["ready_rad"], f"{key}.ready_rad")  # its length is checked with the names
        return ArmDescription(str(table["flange"]), joints, ready)

    needle, probe = arm(needle_table, "needle_arm"), arm(probe_table, "probe_arm")
    shared_table = r.table(data, "shared", {"joints", "ready_rad"}, {"joints", "ready_rad"}) if "shared" in data else {}
    shared = r.strings(shared_table.get("joints", []), "shared.joints")
    shared_ready = r.numbers(shared_table.get("ready_rad", []), "shared.ready_rad")

    # Every coordinate belongs to exactly one group, and the group says which flanges it moves.
    role = {
        "needle_arm.joints": (needle.joints, True, False),
        "probe_arm.joints": (probe.joints, False, True),
        "shared.joints": (shared, True, True),
    }
    seen: dict[str, str] = {}
    for key, (names, moves_needle, moves_probe) in role.items():
        for joint in names:
            if joint not in coordinates:
                why = "it is frozen" if joint in frozen else f"coordinates are {', '.join(joint_names)}"
                raise r.fail(key, f"unknown joint {joint!r} ({why})")
            if joint in seen:
                raise r.fail(key, f"joint {joint!r} is also in {seen[joint]}")
            seen[joint] = key
            actual = (joint in needle_chain, joint in probe_chain)
            if actual != (moves_needle, moves_probe):
                where = {
                    (True, False): "needle_arm.joints",
                    (False, True): "probe_arm.joints",
                    (True, True): "shared.joints",
                    (False, False): "frozen (it moves neither flange)",
                }[actual]
                raise r.fail(key, f"joint {joint!r} belongs in {where}")
    for joint in joint_names:
        if joint not in seen:
            raise r.fail(
                "shared.joints",
                f"joint {joint!r} is in no arm: list it in an arm or shared, or freeze it (frozen.{joint} = value)",
            )
    for key, names, values in (
        ("needle_arm.ready_rad", needle.joints, needle.ready),
        ("probe_arm.ready_rad", probe.joints, probe.ready),
        ("shared.ready_rad", shared, shared_ready),
    ):
        if len(values) != len(names):
            raise r.fail(key, f"must have {len(names)} values (one per joint), got {len(values)}")
        for joint, value in zip(names, values, strict=True):
            k = joint_names.index(joint)
            if not lower[k] <= value <= upper[k]:
                raise r.fail(
                    key,
                    f"{joint} = {value:g} is outside its limits [{lower[k]:g}, {upper[k]:g}]",
                )

    # What a controller publishes.
    controller = r.table(data, "controller", {"mimic", "order"}, set()) if "controller" in data else {}
    mimic_in = controller.get("mimic", {})
    if not isinstance(mimic_in, dict):
        raise r.fail("controller.mimic", f"must be a table of joint = leader, got {_kind(mimic_in)}")
    mimic = {}
    for follower, leader in mimic_in.items():
        leader = r.string(leader, f"controller.mimic.{follower}")
        if follower in coordinates:
            raise r.fail(f"controller.mimic.{follower}", "is a configuration coordinate, not a mimic joint")
        if leader not in coordinates:
            raise r.fail(f"controller.mimic.{follower}", f"unknown joint {leader!r}")
        mimic[follower] = leader
    order = r.strings(controller.get("order", list(joint_names)), "controller.order")
    if sorted(order) != sorted(joint_names):
        missing = sorted(set(joint_names) - set(order)) or sorted(set(order) - set(joint_names))
        raise r.fail("controller.order", f"must list every coordinate once; {missing[0]!r} is missing or unknown")

    model_links = {f.name for f in model.frames if f.type == pin.FrameType.BODY}
    disabled = frozenset(p for p in srdf_pairs if p <= model_links)  # pairs of removed links fall away

    ws = r.table(
        data,
        "workspace",
        {"cube_centre_m", "insertion_dir", "image_depth_dir", "image_lateral_dir"},
        {"cube_centre_m", "insertion_dir", "image_depth_dir", "image_lateral_dir"},
    )
    centre = check_finite(r.numbers(ws["cube_centre_m"], "workspace.cube_centre_m", 3), "workspace.cube_centre_m")
    if not np.all(np.abs(centre) <= MAX_OFFSET_M):
        raise r.fail("workspace.cube_centre_m", f"is beyond {MAX_OFFSET_M:g} m of the base")
    depth = r.direction(ws["image_depth_dir"], "workspace.image_depth_dir")
    lateral = r.direction(ws["image_lateral_dir"], "workspace.image_lateral_dir")
    if abs(float(depth @ lateral)) > 1e-6:
        raise r.fail("workspace.image_lateral_dir", "must be perpendicular to workspace.image_depth_dir")
    workspace = Workspace(
        tuple(centre.tolist()),
        tuple(r.direction(ws["insertion_dir"], "workspace.insertion_dir").tolist()),
        tuple(depth.tolist()),
        tuple(lateral.tolist()),
    )
    for T in mounts.values():
        T.flags.writeable = False
    return Rig(
        name=name,
        source=path,
        summary=summary,
        base=base,
        joint_names=joint_names,
        needle_arm=needle,
        probe_arm=probe,
        shared_joints=shared,
        shared_ready=shared_ready,
        frozen_joints=MappingProxyType(frozen),
        mimic_joints=MappingProxyType(mimic),
        controller_joint_names=order,
        disabled_pairs=disabled,
        mounts=MappingProxyType(mounts),
        workspace=workspace,
    )


# --- where files are ------------------------------------------------------------------------
def example_robot_data_share() -> Path:
    """The installed ``share`` folder of example-robot-data (``…/share/example-robot-data``).

    Found through the package's metadata (the cmeel wheel installs no Python module), so it
    follows whichever environment brachycal runs in.

    Raises:
        InputError: example-robot-data is not installed.
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise InputError("example-robot-data is not installed (pip install example-robot-data)") from None
    return Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data")))


def bundled_description_path(name: str) -> Path:
    """Path of a bundled description, ``brachycal/robots/<name>.toml``."""
    return _robots_folder() / f"{name}.toml"


def _robots_folder() -> Path:
    # Package data next to the code, in the source tree and in an installed wheel alike.
    return Path(__file__).resolve().parents[1] / "robots"


def _resolve(reference: str, folder: Path, key: str, source: Path) -> Path:
    """A file named in a description: ``brachycal:REL`` (bundled data), ``example-robot-data:REL``
    (its share folder) or a path relative to the description's folder."""
    if reference.startswith("brachycal:"):
        path = bundled(*reference.removeprefix("brachycal:").split("/"))
    elif reference.startswith("example-robot-data:"):
        path = example_robot_data_share() / reference.removeprefix("example-robot-data:")
    else:
        path = folder / os.path.expanduser(reference)
    if not os.path.lexists(path):  # anything else there is refused by its reader
        raise InputError(f"key {key!r}: file not found: {reference} ({path})", file=source)
    return path


# --- reading the TOML -----------------------------------------------------------------------
class _Reader:
    """Typed access to the TOML tables; every refusal names the file and the dotted key."""

    def __init__(self, source: Path) -> None:
        self.source = source

    def fail(self, key: str, message: str) -> InputError:
        return InputError(f"key {key!r}: {message}", file=self.source)

    def table(self, data: Mapping[str, Any], key: str, allowed: set[str], required: set[str]) -> dict[str, Any]:
        value = _get(data, key)
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a table, got {_kind(value)}")
        unknown = sorted(set(value) - allowed)
        if unknown:
            raise self.fail(f"{key}.{unknown[0]}", f"unknown key (allowed: {', '.join(sorted(allowed))})")
        missing = sorted(required - set(value))
        if missing:
            raise self.fail(f"{key}.{missing[0]}", "missing")
        return value

    def string(self, value: object, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"must be a non-empty string, got {_kind(value)}")
        return value

    def strings(self, value: object, key: str) -> tuple[str, ...]:
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.fail(key, f"must be a list of names, got {_kind(value)}")
        duplicates = sorted({v for v in value if value.count(v) > 1})
        if duplicates:
            raise self.fail(key, f"{duplicates[0]!r} is listed twice")
        return tuple(value)

    def numbers(self, value: object, key: str, size: int | None = None) -> tuple[float, ...]:
        if not isinstance(value, list) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
        ):
            raise self.fail(key, f"must be a list of numbers, got {_kind(value)}")
        if size is not None and len(value) != size:
            raise self.fail(key, f"must have {size} values, got {len(value)}")
        numbers = tuple(float(v) for v in value)
        if not all(math.isfinite(v) for v in numbers):  # TOML allows nan and inf
            raise self.fail(key, "holds a non-finite value (nan or inf)")
        return numbers

    def transform(self, table: Mapping[str, Any], key: str) -> FloatArray:
        """``(4, 4)`` from ``xyz_m`` and ``rpy_rad`` (URDF's convention), or from a 4x4 ``matrix`` (metres)."""
        if "matrix" in table:
            if "xyz_m" in table or "rpy_rad" in table:
                raise self.fail(f"{key}.matrix", "give either matrix or xyz_m/rpy_rad, not both")
            rows = table["matrix"]
            if not isinstance(rows, list) or len(rows) != 4:
                raise self.fail(f"{key}.matrix", "must be 4 rows of 4 numbers")
            T = np.array([self.numbers(r, f"{key}.matrix", 4) for r in rows])
            T = check_transform(T, f"key '{key}.matrix'", file=self.source)
        else:
            xyz = self.numbers(table.get("xyz_m", [0.0, 0.0, 0.0]), f"{key}.xyz_m", 3)
            rpy = self.numbers(table.get("rpy_rad", [0.0, 0.0, 0.0]), f"{key}.rpy_rad", 3)
            T = from_xyz_rpy(xyz, rpy)
        if not np.all(np.abs(T[:3, 3]) <= MAX_OFFSET_M):
            raise self.fail(key, f"translation {np.round(T[:3, 3], 3).tolist()} m is beyond {MAX_OFFSET_M:g} m")
        return T

    def direction(self, value: object, key: str) -> FloatArray:
        v = np.array(self.numbers(value, key, 3))
        norm = float(np.linalg.norm(v))
        if not norm > 1e-9:
            raise self.fail(key, "must be a non-zero direction")
        return v / norm


def _get(data: Mapping[str, Any], dotted: str) -> object:
    value: object = data
    for part in dotted.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    return value


def _kind(value: object) -> str:
    return {dict: "a table", list: "a list", str: "a string", bool: "a boolean"}.get(type(value), type(value).__name__)


# --- building the URDF ----------------------------------------------------------------------
def _links(root: ET.Element) -> list[str]:
    return [str(link.get("name")) for link in urdf_text.kinematic_links(root)]


def _joints(root: ET.Element) -> dict[str, ET.Element]:
    return {str(joint.get("name")): joint for joint in urdf_text.kinematic_joints(root)}


def _child(joint: ET.Element) -> str:
    node = joint.find("child")
    return "" if node is None else str(node.get("link"))


def _parent(joint: ET.Element) -> str:
    node = joint.find("parent")
    return "" if node is None else str(node.get("link"))


def _root_link(root: ET.Element, source: Path, key: str) -> str:
    children = {_child(j) for j in _joints(root).values()}
    roots = [name for name in _links(root) if name not in children]
    if len(roots) != 1:
        raise InputError(f"key {key!r}: the URDF must have one root link, it has {roots}", file=source)
    return roots[0]


def _resolve_meshes(
    root: ET.Element, urdf_path: Path, base_dir: Path, package_dirs: list[Path], source: Path, *, required: bool = True
) -> None:
    """Rewrite every mesh path relative to ``base_dir`` (``package://NAME/…`` looked up in ``package_dirs``).

    Pinocchio, MuJoCo and ``Robot.write_urdf`` then all find the meshes from ``base_dir`` without a
    ROS package path. A ``package://`` mesh found in none is refused when the meshes are ``required``
    (a dual-arm rig: planning checks collisions), else left as written (kinematics needs no mesh).
    """
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        if filename.startswith("package://"):
            rest = filename.removeprefix("package://")
            found = [d / rest for d in package_dirs if (d / rest).is_file()]
            if not found and not required:
                continue
            if not found:
                raise InputError(
                    f"key 'package_dirs': mesh {filename} of {urdf_path.name} is in none of "
                    f"{[str(d) for d in package_dirs]}",
                    file=source,
                )
            path = found[0]
        elif filename.startswith("file://"):
            path = Path(filename.removeprefix("file://"))
        else:
            path = urdf_path.parent / filename
        mesh.set("filename", os.path.relpath(path.resolve(), base_dir.resolve()))


def _prefixed(root: ET.Element, prefix: str) -> None:
    """Prefix every link and joint name (and the references to them) in place."""
    for link in root.iter("link"):
        link.set("name", prefix + str(link.get("name")))
    for joint in root.iter("joint"):
        if joint.find("parent") is None:  # a <joint> inside <transmission>: dropped with it
            continue
        joint.set("name", prefix + str(joint.get("name")))
        for tag in ("parent", "child"):
            node = joint.find(tag)
            if node is not None:
                node.set("link", prefix + str(node.get("link")))
        mimic = joint.find("mimic")
        if mimic is not None:
            mimic.set("joint", prefix + str(mimic.get("joint")))


def _drop_simulator_elements(root: ET.Element) -> None:
    """Remove ``<transmission>`` and ``<gazebo>``: ROS-control and simulator data, not kinematics."""
    for element in list(root):
        if element.tag in ("transmission", "gazebo"):
            root.remove(element)


def _remove_subtrees(root: ET.Element, links: tuple[str, ...], r: _Reader) -> None:
    """Remove each listed link, every link below it and the joints to them."""
    known = set(_links(root))
    for name in links:
        if name not in known:
            raise r.fail("remove_links", f"no link {name!r} in the URDF")
    joints = _joints(root)
    gone = set(links)
    grown = True
    while grown:
        below = {_child(j) for j in joints.values() if _parent(j) in gone} - gone
        gone |= below
        grown = bool(below)
    for element in list(root):
        if (element.tag == "link" and element.get("name") in gone) or (
            element.tag == "joint" and element.find("child") is not None and _child(element) in gone
        ):
            root.remove(element)


def _freeze(root: ET.Element, frozen: dict[str, float], r: _Reader) -> dict[str, float]:
    """Make each joint fixed at its value (its origin turned or shifted by it); mimic followers of a
    frozen joint freeze with it. Returns every frozen joint with its value."""
    joints = _joints(root)
    values = dict(frozen)
    for name in frozen:
        if name not in joints:
            raise r.fail(f"frozen.{name}", "no such joint in the URDF")
        if joints[name].get("type") not in ("revolute", "continuous", "prismatic"):
            raise r.fail(f"frozen.{name}", f"is a {joints[name].get('type')} joint; only one-axis joints freeze")
        if joints[name].find("mimic") is not None:
            raise r.fail(f"frozen.{name}", "is a mimic joint; freeze the joint it follows")
    for name, joint in joints.items():
        mimic = joint.find("mimic")
        if mimic is not None and mimic.get("joint") in values:
            leader = values[str(mimic.get("joint"))]
            values[name] = float(mimic.get("multiplier", 1.0)) * leader + float(mimic.get("offset", 0.0))
    for name, value in values.items():
        joint = joints[name]
        axis_node = joint.find("axis")
        axis = np.array(
            [float(v) for v in (axis_node.get("xyz", "1 0 0") if axis_node is not None else "1 0 0").split()]
        )
        axis /= np.linalg.norm(axis)
        if joint.get("type") == "prismatic":
            motion = make_transform(np.eye(3), value * axis)
        else:  # Pinocchio's exponential map: scipy would add 0.6 s of import to every load
            motion = make_transform(np.asarray(pin.exp3(value * axis)), np.zeros(3))
        origin = urdf_text.joint_origin(root, name, str(r.source))
        for tag in _MOVING_JOINT_TAGS:
            node = joint.find(tag)
            if node is not None:
                joint.remove(node)
        joint.set("type", "fixed")
        urdf_text.set_joint_origin(root, name, origin @ motion, str(r.source))
    return values


def _add_mujoco_block(root: ET.Element) -> None:
    """MuJoCo keeps fixed links as bodies (so mink can address the tool frames), as the bundled SDA10F's."""
    if root.find("mujoco") is None:
        block = ET.Element("mujoco")
        ET.SubElement(
            block,
            "compiler",
            {"strippath": "true", "fusestatic": "false", "discardvisual": "true", "balanceinertia": "true"},
        )
        root.insert(0, block)


def _add_fixed_frame(root: ET.Element, name: str, parent: str, T_parent_frame: FloatArray, what: str) -> None:
    root.append(ET.Comment(f" brachycal tool frame {name}: {what} (nominal, replaced by calibration) "))
    ET.SubElement(root, "link", {"name": name})
    joint = ET.SubElement(root, "joint", {"name": f"{name}_joint", "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": parent})
    ET.SubElement(joint, "child", {"link": name})
    urdf_text.set_joint_origin(root, f"{name}_joint", T_parent_frame, "<description>")


def _read_urdf(path: Path, key: str, source: Path) -> ET.Element:
    try:
        text = read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES)
    except InputError as exc:
        raise InputError(f"key {key!r}: cannot read {path} ({exc.problem})", file=source) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"key {key!r}: cannot read {path} ({exc})", file=source) from None
    try:
        return urdf_text.parse(text, str(path))
    except InputError as exc:  # say which key named the file, and keep the one line
        raise InputError(f"key {key!r}: {exc}", file=source) from None


def _srdf_pairs(path: Path, prefix: str, key: str, source: Path) -> set[frozenset[str]]:
    try:
        srdf = ET.fromstring(read_input_bytes(path, max_bytes=MAX_DOCUMENT_BYTES))
    except InputError as exc:
        raise InputError(f"key {key!r}: cannot read the SRDF {path} ({exc.problem})", file=source) from None
    except ET.ParseError as exc:
        raise InputError(f"key {key!r}: cannot read the SRDF {path} ({exc})", file=source) from None
    pairs = set()
    for element in srdf.iter("disable_collisions"):
        link1, link2 = element.get("link1"), element.get("link2")
        if not link1 or not link2:
            raise InputError(f"key {key!r}: a <disable_collisions> in {path} lacks link1 or link2", file=source)
        pairs.add(frozenset((prefix + link1, prefix + link2)))
    return pairs


def _chain(model: pin.Model, frame: str) -> list[str]:
    """Names of the joints that move ``frame``, root to frame."""
    jid = model.frames[model.getFrameId(frame)].parentJoint
    names = []
    while jid > 0:
        names.append(str(model.names[jid]))
        jid = model.parents[jid]
    return names[::-1]


def _mount_arms(
    tables: object,
    base: str,
    folder: Path,
    package_dirs: list[Path],
    r: _Reader,
    mounts: dict[str, FloatArray],
    srdf_pairs: set[frozenset[str]],
    meshes_required: bool = True,
) -> tuple[ET.Element, Path]:
    """One URDF of single arms under a new root link ``base``: each arm's links and joints prefixed,
    its root link fixed to ``base`` at the stated pose. Fills ``mounts`` and ``srdf_pairs``."""
    if not isinstance(tables, list) or len(tables) < 1 or not all(isinstance(t, dict) for t in tables):
        raise r.fail("mount", "must be [[mount]] tables, one per arm")
    root = ET.Element("robot", {"name": "cell"})
    root.append(ET.Comment(" built by brachycal from a robot description: single arms mounted on one base "))
    ET.SubElement(root, "link", {"name": base})
    materials: set[str] = set()
    for i, table in enumerate(tables):
        key = f"mount[{i}]"
        table = r.table({key: table}, key, {"prefix", "urdf", "srdf", "xyz_m", "rpy_rad", "matrix"}, {"prefix", "urdf"})
        prefix = r.string(table["prefix"], f"{key}.prefix")
        if prefix in mounts:
            raise r.fail(f"{key}.prefix", f"{prefix!r} is used twice")
        urdf_path = _resolve(r.string(table["urdf"], f"{key}.urdf"), folder, f"{key}.urdf", r.source)
        arm = _read_urdf(urdf_path, f"{key}.urdf", r.source)
        _resolve_meshes(arm, urdf_path, folder, package_dirs, r.source, required=meshes_required)
        _drop_simulator_elements(arm)
        arm_root = _root_link(arm, r.source, f"{key}.urdf")
        _prefixed(arm, prefix)
        if "srdf" in table:
            srdf = _resolve(r.string(table["srdf"], f"{key}.srdf"), folder, f"{key}.srdf", r.source)
            srdf_pairs |= _srdf_pairs(srdf, prefix, f"{key}.srdf", r.source)
        T_base_root = r.transform(table, key)
        mounts[prefix] = T_base_root
        for element in arm:
            if element.tag == "material":  # top-level materials are shared by name: keep the first
                if element.get("name") in materials:
                    continue
                materials.add(str(element.get("name")))
            root.append(element)
        joint = ET.SubElement(root, "joint", {"name": f"{prefix}mount", "type": "fixed"})
        ET.SubElement(joint, "parent", {"link": base})
        ET.SubElement(joint, "child", {"link": prefix + arm_root})
        urdf_text.set_joint_origin(root, f"{prefix}mount", T_base_root, str(r.source))
    names = _links(root)
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise r.fail("mount", f"link {clash[0]!r} appears twice: give each arm its own prefix")
    return root, folder
