"""Hostile input data: corrupted copies of other tools' files (PLUS N-wire recordings, joint logs,
ROS bags, sessions), each refused by the command that reads it with one line naming the file and
the place (frame, row, message, field), exit code 2, nothing written.

Every case builds its input in its own folder from a real file (the PLUS recordings come from the
outside data, see ``conftest.reference``) with one defect: a matrix that is not rigid, a renamed
wire, malformed or truncated XML, a missing field, a joint listed twice, a reading beyond a limit.
"""

from __future__ import annotations

import re
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, reference
from hostile import Case, check_refusal

from brachycal.data import write_bag_log
from brachycal.model import Robot

CONFIG = "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
FRAMES = "fCal_3NWires_segmented_frames.xml"
NWIRE = ["nwire", "{tmp}/config.xml", "{tmp}/frames.xml", "--out", "{tmp}/nwire.json"]
FK = ["fk", "{tmp}/log.csv", "--frames", "needle_tip", "--out", "{tmp}/poses.csv", "--quiet"]
CALIBRATE = ["calibrate", "{tmp}/session", "--out", "{tmp}/result.json", "--quiet"]


# --- PLUS N-wire inputs -----------------------------------------------------------------------------
def plus_files(edit_config: Callable[[ET.Element], None] | None = None, edit_frames=None, raw_frames=None):
    """Copy PLUS's fCal config and frames to ``config.xml``/``frames.xml``, one of them edited.

    ``edit_*`` change the parsed tree; ``raw_frames`` changes the frames file's text.
    """

    def setup(tmp: Path) -> None:
        for name, target, edit in ((CONFIG, "config.xml", edit_config), (FRAMES, "frames.xml", edit_frames)):
            source = reference("plus_fcal_nwire", name)
            if edit is None:
                shutil.copyfile(source, tmp / target)
                continue
            tree = ET.parse(source)
            edit(tree.getroot())
            tree.write(tmp / target)
        if raw_frames is not None:
            (tmp / "frames.xml").write_text(raw_frames((tmp / "frames.xml").read_text()))

    return setup


def first_frame(root: ET.Element, which: str = "CalibrationData") -> ET.Element:
    return root.find(f".//{which}/Frame")


def frame_field(name: str, change: Callable[[str], str | None], which: str = "CalibrationData"):
    """Edit field ``name`` of the first frame of ``which``; ``change`` returning None removes it."""

    def edit(root: ET.Element) -> None:
        for element in first_frame(root, which).iter("CustomFrameField"):
            if element.get("Name") == name:
                value = change(element.get("Value"))
                if value is None:
                    element.set("Name", "Removed" + name)
                else:
                    element.set("Value", value)
                return
        raise AssertionError(f"no field {name}")

    return edit


def scale_rotation(text: str, factor: float = 1.5) -> str:
    """A 4×4 (row-major text) with its rotation block multiplied by ``factor``."""
    M = np.array(text.split(), dtype=float).reshape(4, 4)
    M[:3, :3] *= factor
    return " ".join(repr(float(v)) for v in M.ravel())


def rename_wire(old: str, new: str, *, everywhere: bool = False):
    def edit(root: ET.Element) -> None:
        scope = root if everywhere else first_frame(root)
        for point in scope.iter("Point"):
            if point.get("WireName") == old:
                point.set("WireName", new)

    return edit


def scale_phantom_registration(root: ET.Element) -> None:
    for element in root.iter("Transform"):
        if (element.get("From"), element.get("To")) == ("Phantom", "Reference"):
            element.set("Matrix", scale_rotation(element.get("Matrix"), 1.5))


def set_wire_attribute(attribute: str, value: str):
    def edit(root: ET.Element) -> None:
        next(w for w in root.iter("Wire") if w.get("Name") == "8:L1_h1").set(attribute, value)

    return edit


def rename_configured_wire(root: ET.Element) -> None:
    for wire in root.iter("Wire"):
        if wire.get("Name") == "8:L1_h1":
            wire.set("Name", "8:L1_hX")


def make_diagonal_parallel(root: ET.Element) -> None:
    for wire in root.iter("Wire"):
        if wire.get("Name") == "8:L1_h1":
            wire.set("EndPointBack", "55.0 40.0 20.0")  # parallel to its side wires: not an N


def drop_point(root: ET.Element) -> None:
    segmented = first_frame(root).find("SegmentedPoints")
    segmented.remove(next(p for p in segmented if p.get("WireName") == "5:H3_l3"))


def set_spacing(value: str):
    def edit(root: ET.Element) -> None:
        next(root.iter("Segmentation")).set("ApproximateSpacingMmPerPixel", value)

    return edit


def same_pixel_for_outer_wires(root: ET.Element) -> None:
    frame = first_frame(root)
    points = {p.get("WireName"): p for p in frame.iter("Point")}
    points["9:M1_m1"].set("Position", points["7:G1_g1"].get("Position"))


def drop_wire_name(root: ET.Element) -> None:
    del next(first_frame(root).iter("Point")).attrib["WireName"]


def duplicate_point(root: ET.Element) -> None:
    segmented = first_frame(root).find("SegmentedPoints")
    segmented.append(ET.Element("Point", dict(segmented[0].attrib)))


def set_index(value: str):
    def edit(root: ET.Element) -> None:
        first_frame(root).set("Index", value)

    return edit


def truncate_text(fraction: float):
    return lambda text: text[: int(len(text) * fraction)]


# --- joint logs, bags, sessions ---------------------------------------------------------------------
_ROBOT: list[Robot] = []


def robot() -> Robot:
    if not _ROBOT:
        _ROBOT.append(Robot.load())
    return _ROBOT[0]


def csv_log(edit: Callable[[list[str], list[list[str]]], None]):
    """The example joint log copied to ``log.csv``, ``edit(header, rows)`` applied."""

    def setup(tmp: Path) -> None:
        lines = (ROOT / "examples" / "joint_log.csv").read_text().splitlines()
        header, rows = lines[0].split(","), [line.split(",") for line in lines[1:]]
        edit(header, rows)
        (tmp / "log.csv").write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")

    return setup


def duplicate_column(header: list[str], rows: list[list[str]]) -> None:
    k = header.index("arm_right_joint_2_l")
    header.append("arm_right_joint_2_l")
    for row in rows:
        row.append(repr(float(row[k]) + 0.05))


def beyond_limit(by: float, column: str = "arm_left_joint_2_l", row: int = 3):
    def edit(header: list[str], rows: list[list[str]]) -> None:
        k = robot().joint_names.index(column)
        rows[row - 2][header.index(column)] = repr(float(robot().upper[k]) + by)

    return edit


def bag_with_a_joint_twice(tmp: Path) -> None:
    names = [*robot().joint_names, "arm_right_joint_2_l"]
    q = np.zeros((3, len(names)))
    q[:, -1] = 0.05  # a second, different reading of arm_right_joint_2_l
    write_bag_log(tmp / "log.bag", 1.7e9 + np.arange(3.0), q, names, ros=1)


def ros2_bag_with_message_count(count: str):
    """A ROS 2 bag whose ``metadata.yaml`` states ``message_count: <count>`` for its topic."""

    def setup(tmp: Path) -> None:
        folder = write_bag_log(tmp / "log_bag", 1.7e9 + np.arange(3.0), np.zeros((3, 15)), robot().joint_names, ros=2)
        metadata = folder / "metadata.yaml"
        metadata.write_text(metadata.read_text().replace("message_count: 3", f"message_count: {count}"))

    return setup


def session(file: str, row: int, column: str, value: Callable[[float], float]):
    def setup(tmp: Path) -> None:
        shutil.copytree(ROOT / "examples" / "session_exact", tmp / "session")
        path = tmp / "session" / file
        lines = path.read_text().splitlines()
        header = lines[0].split(",")
        fields = lines[row - 1].split(",")
        k = robot().joint_names.index(column)
        fields[header.index(column)] = repr(value(float(robot().upper[k])))
        lines[row - 1] = ",".join(fields)
        path.write_text("\n".join(lines) + "\n")

    return setup


def unchanged(header: list[str], rows: list[list[str]]) -> None:
    """The example log as it is: the case's refusal comes from its options."""


def set_text(row: int, column: str, text: str):
    """A log edit: file row ``row`` (header = 1), ``column`` set to ``text`` as written."""

    def edit(header: list[str], rows: list[list[str]]) -> None:
        rows[row - 2][header.index(column)] = text

    return edit


def cut_file(name: str, drop: int):
    """``name`` (already in the folder) without its final newline and last ``drop`` characters: a
    file cut mid-number (``1.608151017`` → ``1.60``) by a killed writer."""

    def edit(tmp: Path) -> None:
        path = tmp / name
        path.write_text(path.read_text().rstrip("\n")[:-drop])

    return edit


def then(*setups: Callable[[Path], None]):
    def setup(tmp: Path) -> None:
        for step in setups:
            step(tmp)

    return setup


def write_file(name: str, text: str):
    def setup(tmp: Path) -> None:
        (tmp / name).write_text(text)

    return setup


def pose_list(edit: Callable[[list[str]], list[str]] = lambda lines: lines, scale: float = 1.0):
    """The bundled pivot example (millimetres) as ``poses.csv``: translations times ``scale``, then ``edit(lines)``."""

    def setup(tmp: Path) -> None:
        lines = (ROOT / "examples" / "pivot" / "pointer_pivot.csv").read_text().splitlines()
        header = lines[0].split(",")
        if scale != 1.0:
            moved = [header.index(c) for c in ("m03", "m13", "m23")]
            for k in range(1, len(lines)):
                fields = lines[k].split(",")
                for c in moved:
                    fields[c] = repr(float(fields[c]) * scale)
                lines[k] = ",".join(fields)
        (tmp / "poses.csv").write_text("\n".join(edit(lines)) + "\n")

    return setup


def pose_field(row: int, column: str, text: str):
    """A pose-list edit: file row ``row`` (header = 1), ``column`` set to ``text``."""

    def edit(lines: list[str]) -> list[str]:
        header = lines[0].split(",")
        fields = lines[row - 1].split(",")
        fields[header.index(column)] = text
        lines[row - 1] = ",".join(fields)
        return lines

    return edit


def session_text(file: str, change: Callable[[str], str]):
    def setup(tmp: Path) -> None:
        shutil.copytree(ROOT / "examples" / "session_exact", tmp / "session")
        path = tmp / "session" / file
        path.write_text(change(path.read_text()))

    return setup


PIVOT = ["pivot", "{tmp}/poses.csv", "--out", "{tmp}/pivot.json"]


def copied_row(line: int, old: str, new: str) -> Callable[[str], str]:
    """A session file's text with file line ``line`` appended again, its first field ``old`` as ``new``."""

    def change(text: str) -> str:
        copy = text.splitlines()[line - 1]
        assert copy.startswith(old)
        return text + new + copy[len(old) :] + "\n"

    return change


CASES = [
    # Numbers that parse but are wrong: one grammar (what CSV writers write), a cut last line refused.
    Case(
        "fk-csv-digit-separator",
        FK,
        ("log.csv", "row 3", "arm_left_joint_2_l", "'0_1' is not a number"),
        csv_log(set_text(3, "arm_left_joint_2_l", "0_1")),
    ),
    Case(
        "fk-csv-hexadecimal",
        FK,
        ("log.csv", "row 4", "time", "'0x10' is not a number"),
        csv_log(set_text(4, "time", "0x10")),
    ),
    Case(
        "fk-csv-blank-inside-a-number",
        FK,
        ("log.csv", "row 3", "arm_left_joint_2_l", "'0 .1' is not a number"),
        csv_log(set_text(3, "arm_left_joint_2_l", "0 .1")),
    ),
    Case(
        "fk-csv-exponent-without-digits",
        FK,
        ("log.csv", "row 3", "arm_left_joint_2_l", "'1e' is not a number"),
        csv_log(set_text(3, "arm_left_joint_2_l", " 1e ")),
    ),
    Case(
        "fk-csv-old-mac-line-ends",
        FK,
        ("log.csv", "carriage return alone", "LF or CRLF"),
        lambda tmp: (tmp / "log.csv").write_bytes(
            (ROOT / "examples" / "joint_log.csv").read_bytes().replace(b"\n", b"\r")
        ),
    ),
    Case(
        "fk-csv-arabic-indic-digit",
        FK,
        ("log.csv", "row 3", "arm_left_joint_2_l", "is not a number"),
        csv_log(set_text(3, "arm_left_joint_2_l", "\u0660")),
    ),
    Case(
        "fk-csv-infinity",
        FK,
        ("log.csv", "row 5", "time", "'infinity' is not a number"),
        csv_log(set_text(5, "time", "infinity")),
    ),
    Case(
        "fk-csv-number-beyond-float-range",
        FK,
        ("log.csv", "row 3", "arm_left_joint_2_l", "not a finite number", "1e999"),
        csv_log(set_text(3, "arm_left_joint_2_l", "1e999")),
    ),
    Case(
        "fk-csv-cut-mid-number",
        FK,
        ("log.csv", "row", "the last line has no newline", "truncated"),
        then(csv_log(unchanged), cut_file("log.csv", 7)),
    ),
    Case(
        "fk-times-header-only",
        [*FK, "--times", "{tmp}/times.csv"],
        ("times.csv", "no times"),
        then(csv_log(unchanged), write_file("times.csv", "time\n")),
    ),
    Case(
        "fk-times-cut",
        [*FK, "--times", "{tmp}/times.csv"],
        ("times.csv, row 3", "the last line has no newline"),
        then(csv_log(unchanged), write_file("times.csv", "time\n0.5\n1.6")),
    ),
    Case(
        "fk-out-trailing-slash",
        [*FK[:-3], "--out", "{tmp}/poses/", "--quiet"],
        ("--out", "names a folder"),
        csv_log(unchanged),
    ),
    Case(
        "fk-out-existing-folder",
        [*FK[:-3], "--out", "{tmp}", "--quiet", "--force"],
        ("is a folder",),
        csv_log(unchanged),
    ),
    # Pose lists and pivot: absurd magnitudes, cut files, the wrong unit (a 396 m or a 0.4 mm tool at exit 0).
    Case(
        "pivot-millimetres-read-as-metres",
        PIVOT,
        ("poses.csv", "m from the tool's origin", "read with --units m", "--units mm"),
        pose_list(),
    ),
    Case(
        "pivot-metres-read-as-millimetres",
        [*PIVOT, "--units", "mm"],
        ("poses.csv", "mm from the tool's origin", "read with --units mm", "--units m"),
        pose_list(scale=1e-3),
    ),
    Case(
        "pivot-translation-1e308",
        [*PIVOT, "--units", "mm"],
        ("poses.csv", "row 4", "m13", "not a physical position"),
        pose_list(pose_field(4, "m13", "1e308")),
    ),
    Case(
        "pivot-digit-separator",
        [*PIVOT, "--units", "mm"],
        ("poses.csv", "row 2", "m03", "'-2_18.4' is not a number"),
        pose_list(pose_field(2, "m03", "-2_18.4")),
    ),
    Case(
        "pivot-pose-list-cut",
        [*PIVOT, "--units", "mm"],
        ("poses.csv", "the last line has no newline"),
        then(pose_list(), cut_file("poses.csv", 2)),
    ),
    # Sessions: a tip, a trial beyond any physical value (LinAlgError, OverflowError before).
    Case(
        "calibrate-session-tip-1e308",
        CALIBRATE,
        ("session.toml", "tip_in_flange_mm", "not a physical position"),
        session_text("session.toml", lambda t: t.replace("[0.0, 0.0, 150.0]", "[0.0, 1e308, 150.0]")),
    ),
    Case(
        "calibrate-session-trial-infinite",
        CALIBRATE,
        ("touches.csv", "row 2", "trial", "not a finite number"),
        session_text("touches.csv", lambda t: t.replace("top_model,rtip1,1,", "top_model,rtip1,inf,", 1)),
    ),
    Case(
        "calibrate-session-trial-1e308",
        CALIBRATE,
        ("touches.csv", "row 2", "trial", "from 1 to 10000"),
        session_text("touches.csv", lambda t: t.replace("top_model,rtip1,1,", "top_model,rtip1,1e308,", 1)),
    ),
    Case(
        "calibrate-session-samples-cut",
        CALIBRATE,
        ("samples.csv", "the last line has no newline"),
        session_text("samples.csv", lambda t: t.rstrip("\n")[:-3]),
    ),
    # fk --lag-s: a finite number, and only with --times (the times it shifts)
    Case("fk-lag-without-times", [*FK, "--lag-s", "0.05"], ("--lag-s applies to --times",), csv_log(unchanged)),
    Case("fk-lag-not-a-number", [*FK, "--lag-s", "nan"], ("--lag-s", "nan"), csv_log(unchanged)),
    # N-wire: tracker and phantom matrices must be rigid (a rotation ×1.5 gave a wrong spacing and a
    # normal-looking validation error, exit 0).
    Case(
        "nwire-probe-to-tracker-rotation-scaled",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "ProbeToTrackerTransform", "not a rigid transform"),
        plus_files(edit_frames=frame_field("ProbeToTrackerTransform", scale_rotation)),
    ),
    Case(
        "nwire-reference-to-tracker-rotation-scaled-in-validation",
        NWIRE,
        ("frames.xml", "ValidationData Frame 0", "ReferenceToTrackerTransform", "not a rigid transform"),
        plus_files(edit_frames=frame_field("ReferenceToTrackerTransform", scale_rotation, "ValidationData")),
    ),
    Case(
        "nwire-phantom-registration-scaled",
        NWIRE,
        ("config.xml", "Phantom->Reference", "not a rigid transform"),
        plus_files(edit_config=scale_phantom_registration),
    ),
    # Wire names must match the configuration (a renamed wire dropped a pattern and wrote NaN).
    Case(
        "nwire-wire-renamed-in-one-frame",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "'7:G1_gX'", "config.xml", "'7:G1_g1'"),
        plus_files(edit_frames=rename_wire("7:G1_g1", "7:G1_gX")),
    ),
    Case(
        "nwire-wire-renamed-in-the-configuration",
        NWIRE,
        ("frames.xml", "'8:L1_h1'", "config.xml", "'8:L1_hX'"),
        plus_files(edit_config=rename_configured_wire),
    ),
    Case(
        "nwire-frame-lacks-a-wire",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "lacks", "'5:H3_l3'", "config.xml"),
        plus_files(edit_frames=drop_point),
    ),
    Case(
        "nwire-configured-diagonal-parallel-to-its-sides",
        NWIRE,
        ("config.xml", "PhantomDefinition/Geometry/Pattern[1]", "'7:G1_g1' is parallel to the diagonal '8:L1_h1'"),
        plus_files(edit_config=make_diagonal_parallel),
    ),
    Case(
        "nwire-point-without-wire-name",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "no WireName"),
        plus_files(edit_frames=drop_wire_name),
    ),
    Case(
        "nwire-wire-segmented-twice",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "segmented twice"),
        plus_files(edit_frames=duplicate_point),
    ),
    Case(
        "nwire-outer-wires-at-one-pixel",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "same pixel"),
        plus_files(edit_frames=same_pixel_for_outer_wires),
    ),
    # Malformed, truncated, missing fields.
    Case(
        "nwire-frames-truncated",
        NWIRE,
        ("frames.xml", "not valid XML"),
        plus_files(raw_frames=truncate_text(0.5)),
    ),
    Case(
        "nwire-frames-empty",
        NWIRE,
        ("frames.xml", "not valid XML"),
        plus_files(raw_frames=truncate_text(0.0)),
    ),
    Case(
        "nwire-frames-not-xml",
        NWIRE,
        ("frames.xml", "not valid XML"),
        plus_files(raw_frames=lambda text: "time,x\n0,1\n"),
    ),
    Case(
        "nwire-frames-unsafe-entities",
        NWIRE,
        ("frames.xml", "refused unsafe XML"),
        plus_files(raw_frames=lambda text: '<!DOCTYPE l [<!ENTITY a "aaaa">]>' + re.sub(r"^<\?xml[^>]*>", "", text)),
    ),
    Case(
        "nwire-frame-without-reference-to-tracker",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "missing ReferenceToTrackerTransform"),
        plus_files(edit_frames=frame_field("ReferenceToTrackerTransform", lambda v: None)),
    ),
    Case(
        "nwire-transform-with-15-numbers",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "ProbeToTrackerTransform", "expected 16"),
        plus_files(edit_frames=frame_field("ProbeToTrackerTransform", lambda v: " ".join(v.split()[:15]))),
    ),
    Case(
        "nwire-transform-with-nan",
        NWIRE,
        ("frames.xml", "CalibrationData Frame 0", "ProbeToTrackerTransform", "finite"),
        plus_files(edit_frames=frame_field("ProbeToTrackerTransform", lambda v: "nan " + " ".join(v.split()[1:]))),
    ),
    Case(
        "nwire-frame-index-not-a-number",
        NWIRE,
        ("frames.xml", "CalibrationData Frame", "whole number", "'x'"),
        plus_files(edit_frames=set_index("x")),
    ),
    Case(
        "nwire-spacing-not-a-number",
        NWIRE,
        ("config.xml", "ApproximateSpacingMmPerPixel", "expected 1 finite number, got '0.078mm'"),
        plus_files(edit_config=set_spacing("0.078mm")),
    ),
    Case(
        "nwire-wire-end-1e308",
        NWIRE,
        ("config.xml", "EndPointFront", "within ±10000", "'1e308 40.0 0.0'"),
        plus_files(edit_config=set_wire_attribute("EndPointFront", "1e308 40.0 0.0")),
    ),
    Case(
        "nwire-wire-end-digit-separator",
        NWIRE,
        ("config.xml", "EndPointFront", "expected 3 finite numbers", "'5_5.0 40.0 0.0'"),
        plus_files(edit_config=set_wire_attribute("EndPointFront", "5_5.0 40.0 0.0")),
    ),
    Case(
        "nwire-spacing-negative",
        NWIRE,
        ("config.xml", "ApproximateSpacingMmPerPixel", "positive"),
        plus_files(edit_config=set_spacing("-0.078")),
    ),
    Case(
        "nwire-config-and-frames-swapped",
        ["nwire", "{tmp}/frames.xml", "{tmp}/config.xml", "--out", "{tmp}/nwire.json"],
        ("frames.xml", "no N-wire patterns"),
        plus_files(),
    ),
    # Joint logs and bags: a joint listed twice (the bag was read silently: needle tip off by up
    # to 58 mm), readings beyond a limit by more than encoder noise.
    Case(
        "fk-csv-joint-listed-twice",
        FK,
        ("log.csv", "row 1", "arm_right_joint_2_l", "appears twice"),
        csv_log(duplicate_column),
    ),
    Case(
        "fk-bag-joint-listed-twice",
        ["fk", "{tmp}/log.bag", "--frames", "needle_tip", "--out", "{tmp}/poses.csv", "--quiet"],
        ("log.bag", "message 1", "'arm_right_joint_2_l' listed twice"),
        bag_with_a_joint_twice,
    ),
    *(
        Case(
            f"fk-ros2-bag-message-count-{name}",
            ["fk", "{tmp}/log_bag", "--frames", "needle_tip", "--out", "{tmp}/poses.csv", "--quiet"],
            ("log_bag/metadata.yaml", "message_count", "'/joint_states'", "not a whole number"),
            ros2_bag_with_message_count(count),
        )
        for name, count in [("inf", "inf"), ("float-inf", ".inf"), ("negative", "-1"), ("fraction", "2.5")]
    ),
    Case(
        "fk-csv-beyond-limit-by-more-than-encoder-noise",
        FK,
        ("log.csv", "row 3", "arm_left_joint_2_l", "outside the joint limits", "0.001 rad"),
        csv_log(beyond_limit(2e-3)),
    ),
    # A sample copied under a new name: it would count twice in the fit.
    Case(
        "calibrate-session-sample-copied-under-a-new-name",
        CALIBRATE,
        ("samples.csv", "row 66", "sample 's_copy' has the joints and pixel of sample 's004' (row 5)"),
        session_text("samples.csv", copied_row(5, "s004,", "s_copy,")),
    ),
    Case(
        "calibrate-session-beyond-limit-by-more-than-encoder-noise",
        CALIBRATE,
        ("samples.csv", "row 5", "arm_right_joint_7_t", "outside the joint limits"),
        session("samples.csv", 5, "arm_right_joint_7_t", lambda upper: upper + 1.5e-3),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_data_refusals(case, tmp_path):
    check_refusal(case, tmp_path)
