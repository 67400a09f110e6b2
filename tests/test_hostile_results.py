"""Hostile result files (``brachycal-result/1``) given to every command that reads one: ``locate``,
``export``, ``verify``, ``plan --result`` and ``view``.

Each row is refused as every refusal must be (:func:`hostile.check_refusal`): exit code 2, one
line naming the file and the place in the document (``transforms.Ptip_T_I.chain``), nothing
written. The rows cover wrong types and shapes, non-finite and out-of-range numbers, improper
rotations, deep nesting, huge integers and files that are not regular or too large.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli

from brachycal.data.json_files import MAX_JSON_BYTES

SESSION = ROOT / "examples" / "twin_session"
JOINTS = ROOT / "examples" / "joint_log.csv"
RESULT = "{tmp}/result.json"
#: A joint whose zero offset the base result stores (the SDA10F's left arm's first joint).
JOINT = "arm_left_joint_1_s"

#: Each command that reads a result, with ``{result}`` where the result goes. The other inputs do
#: not exist: the result is read first, and a result wrongly accepted then fails on them, not hangs.
COMMANDS: dict[str, list[str]] = {
    "locate": ["locate", "{result}", str(JOINTS), "--uv", "540,300"],
    "export": ["export", "{result}", "--out", "{tmp}/x"],
    "verify": ["verify", "{result}", "{tmp}/no_check", "--out", "{tmp}/record.json"],
    "plan": ["plan", "--result", "{result}", "--points", "2", "--out", "{tmp}/plan.csv", "--quiet"],
    "view": ["view", "{result}", "--session", "{tmp}/no_session"],
}

BASE: dict[str, Path] = {}


def edited(edit: Callable[[dict], object]) -> Callable[[Path], None]:
    """Setup: ``{tmp}/result.json`` = the base result with ``edit(document)`` applied (``json.dumps``
    writes NaN and infinities as ``NaN``/``Infinity``, as Python's ``json`` reads them)."""

    def setup(tmp: Path) -> None:
        document = json.loads(BASE["result"].read_text())
        edit(document)
        (tmp / "result.json").write_text(json.dumps(document))

    return setup


def text_with(key: str, value_text: str) -> Callable[[Path], None]:
    """Setup: the base result with a top-level ``key`` whose value is ``value_text``, as written."""

    def setup(tmp: Path) -> None:
        text = BASE["result"].read_text().rstrip()
        assert text.endswith("}")
        (tmp / "result.json").write_text(f'{text[:-1]}, "{key}": {value_text}}}')

    return setup


def at(*keys: str | int, value: object) -> Callable[[dict], None]:
    """Edit: set the value at ``keys``."""

    def edit(document: dict) -> None:
        node = document
        for key in keys[:-1]:
            node = node[key]
        node[keys[-1]] = value

    return edit


def transform_edit(*keys: str, change: Callable[[np.ndarray], np.ndarray]) -> Callable[[dict], None]:
    def edit(document: dict) -> None:
        node = document
        for key in keys[:-1]:
            node = node[key]
        node[keys[-1]] = change(np.array(node[keys[-1]], dtype=float)).tolist()

    return edit


def mirrored(T: np.ndarray) -> np.ndarray:
    T[:3, 0] *= -1.0  # a reflection: orthonormal, det -1
    return T


def scaled(T: np.ndarray) -> np.ndarray:
    T[:3, :3] *= 1.01
    return T


def in_millimetres(T: np.ndarray) -> np.ndarray:
    T[:3, 3] = [1000.0, 0.0, 0.0]
    return T


def fifo(tmp: Path) -> None:
    os.mkfifo(tmp / "result.json")


def folder(tmp: Path) -> None:
    (tmp / "result.json").mkdir()


def too_large(tmp: Path) -> None:
    with open(tmp / "result.json", "wb") as stream:  # sparse: no disk used
        stream.truncate(MAX_JSON_BYTES + 1)


ORIGIN = ("chain", "robot_joint_origins", JOINT)

#: (id, setup, words the refusal names besides the file). ``{result}`` is ``{tmp}/result.json``.
ROWS: list[tuple[str, Callable[[Path], None], tuple[str, ...]]] = [
    ("spacing-is-a-list", edited(at("spacing_mm", value=[0.19, 0.19])), ("spacing_mm", "object")),
    ("chain-is-a-list", edited(at("chain", value=[1, 2])), ("'chain'", "object")),
    ("transforms-is-a-string", edited(at("transforms", value="identity")), ("'transforms'", "object")),
    ("joint-offset-nan", edited(at("chain", "joint_offsets_rad", JOINT, value=float("nan"))), (JOINT, "NaN")),
    ("joint-offset-string", edited(at("chain", "joint_offsets_rad", JOINT, value="0.01")), (JOINT, "number")),
    ("joint-offset-1e6-rad", edited(at("chain", "joint_offsets_rad", JOINT, value=1e6)), (JOINT, "1e+06 rad")),
    ("nested-100000-deep", text_with("extra", "[" * 100_000 + "]" * 100_000), ("nested", "64")),
    ("nested-65-deep", text_with("extra", "[" * 65 + "]" * 65), ("'extra[0][0]", "nested")),
    ("integer-of-5000-digits", text_with("extra", "7" * 5000), ("'extra'", "5000 digits")),
    ("image-size-of-5000-digits", edited(at("image", "size_px", value=[10**4000, 720])), ("image.size_px[0]",)),
    ("n-huge", edited(at("loocv", "chain", "n", value=10**30)), ("loocv.chain.n", "digits")),
    ("error-infinity", edited(at("loocv", "chain", "errors_mm", 3, value=float("inf"))), ("errors_mm[3]", "Infinity")),
    ("error-minus-infinity", edited(at("spacing_mm", "chain", 1, value=-float("inf"))), ("chain[1]", "-Infinity")),
    ("number-beyond-float", text_with("extra", "[1e400]"), ("'extra[0]'", "1e400", "finite")),
    ("error-negative", edited(at("loocv", "chain", "rmse_mm", value=-0.5)), ("loocv.chain.rmse_mm", ">= 0")),
    (
        "image-transform-mirrored",
        edited(transform_edit("transforms", "Ptip_T_I", "chain", change=mirrored)),
        ("transforms.Ptip_T_I.chain", "determinant -1"),
    ),
    (
        "needle-tip-in-millimetres",
        edited(transform_edit("transforms", "ER_T_Ntip", change=in_millimetres)),
        ("transforms.ER_T_Ntip", "1000 m", "5 m"),
    ),
    (
        "probe-transform-3-rows",
        edited(at("transforms", "EL_T_Ptip", value=np.eye(4)[:3].tolist())),
        ("transforms.EL_T_Ptip", "4 values"),
    ),
    (
        "probe-transform-entry-text",
        edited(at("transforms", "EL_T_Ptip", 0, 3, value="0.1")),
        ("transforms.EL_T_Ptip[0][3]", "number"),
    ),
    (
        "joint-origin-scaled",
        edited(transform_edit(*ORIGIN, "corrected", change=scaled)),
        (f"chain.robot_joint_origins.{JOINT}.corrected", "not a rigid transform"),
    ),
    (
        "joint-origin-without-urdf",
        edited(at(*ORIGIN, value={"corrected": np.eye(4).tolist()})),
        (f"chain.robot_joint_origins.{JOINT}.urdf", "missing"),
    ),
    ("unknown-method", edited(at("transforms", "Ptip_T_I", "magic", value=np.eye(4).tolist())), ("magic", "unknown")),
    ("spacing-missing", edited(at("spacing_mm", value={})), ("spacing_mm.chain", "missing")),
    ("spacing-in-metres", edited(at("spacing_mm", "chain", value=[1.9e-4, 1.9e-4])), ("spacing_mm.chain", "metres")),
    ("spacing-nested", edited(at("spacing_mm", "chain", value=[[0.19, 0.19]])), ("spacing_mm.chain", "2 values")),
    ("image-size-zero", edited(at("image", "size_px", value=[0, 720])), ("image.size_px", "whole numbers")),
    ("reference-tip-two-numbers", edited(at("reference_tips_m", "rtip1", value=[0.1, 0.2])), ("rtip1", "3 values")),
    ("robot-without-joints", edited(at("robot", "joint_names", value=[])), ("robot.joint_names", "empty")),
    ("robot-name-a-number", edited(at("robot", "name", value=7)), ("robot.name", "string")),
    ("samples-not-names", edited(at("samples", 0, value={"id": 1})), ("samples[0]", "string")),
    ("refused-reason-not-text", edited(at("refused", value={"kabsch": 3})), ("refused.kabsch", "string")),
    ("sound-speed-of-light", edited(at("chain", "sound_speed_m_s", value=3e8)), ("chain.sound_speed_m_s", "m/s")),
    ("key-of-100000-characters", edited(at("inputs", "k" * 100_000, value=5)), ("inputs.kkkk", "...", "string")),
    ("other-format", edited(at("format", value="brachycal-result/2")), ("'format'", "brachycal-result/2")),
    ("not-an-object", lambda tmp: (tmp / "result.json").write_text("[1, 2]"), ("'format'",)),
    ("not-json", lambda tmp: (tmp / "result.json").write_text('{"format": '), ("not valid json",)),
    ("not-utf8", lambda tmp: (tmp / "result.json").write_bytes(b'{"format": "\xff"}'), ("not valid json",)),
    ("a-fifo", fifo, ("is a fifo",)),
    ("a-folder", folder, ("is a folder",)),
    ("larger-than-the-cap", too_large, ("larger than 64 MB",)),
]

CASES = [
    Case(
        f"{command}-{name}",
        [a.replace("{result}", RESULT) for a in argv],
        ("result.json", *words),
        setup,
    )
    for name, setup, words in ROWS
    for command, argv in COMMANDS.items()
] + [
    Case(f"{command}-a-device", [a.replace("{result}", "/dev/zero") for a in argv], ("/dev/zero", "is a device"))
    for command, argv in COMMANDS.items()
]


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> dict[str, Path]:
    """A whole-chain result with joint offsets (and so corrected joint origins), outside the cases'
    folders: it holds every block the edits above change."""
    result = tmp_path_factory.mktemp("inputs") / "result.json"
    argv = ["calibrate", str(SESSION), "--solve", "chain", "--joint-offsets", "--out", str(result), "--quiet"]
    outcome = run_cli(argv)
    assert outcome.code == 0, outcome.err
    document = json.loads(result.read_text())
    assert JOINT in document["chain"]["joint_offsets_rad"] and JOINT in document["chain"]["robot_joint_origins"]
    document["refused"] = {"kabsch": "example reason"}  # accepted: see test_the_base_result_is_accepted
    result.write_text(json.dumps(document))
    BASE["result"] = result
    return BASE


def test_the_base_result_is_accepted(base, tmp_path):
    # Every refusal below is the edit's: the unedited file is read by each command.
    outcome = run_cli(["locate", str(base["result"]), str(JOINTS), "--uv", "540,300"])
    assert outcome.code == 0, outcome.err


def test_ids_are_unique():
    ids = [case.id for case in CASES]
    assert len(ids) == len(set(ids))


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_result_file_refusals(case, tmp_path, base):
    check_refusal(case, tmp_path)
