"""Hostile inputs to ``brachycal verify`` and ``brachycal plan check``: each refused as every
refusal must be (:func:`hostile.check_refusal`): exit code 2, one line naming the file, row,
column or option, nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hostile import Case, check_refusal, run_cli

OUT = ["--out", "{tmp}/record.json"]


def copy_check(edit=None, drop: str | None = None):
    """Setup: the good check session copied to ``{tmp}/check``, then edited or a file dropped."""

    def setup(tmp: Path) -> None:
        shutil.copytree(GOOD["check"], tmp / "check")
        if drop:
            (tmp / "check" / drop).unlink()
        if edit:
            edit(tmp / "check")

    return setup


def copy_result(edit):
    def setup(tmp: Path) -> None:
        data = json.loads(Path(GOOD["result"]).read_text())
        edit(data)
        (tmp / "result.json").write_text(json.dumps(data))

    return setup


def replace_in(name: str, old: str, new: str, count: int = 1):
    def edit(folder: Path) -> None:
        path = folder / name
        text = path.read_text()
        assert old in text, f"{old!r} not in {name}"
        path.write_text(text.replace(old, new, count))

    return edit


def bad_sample_value(folder: Path) -> None:
    path = folder / "samples.csv"
    lines = path.read_text().splitlines()
    fields = lines[2].split(",")
    fields[-1] = "abc"  # v_px of the second sample (file row 3)
    lines[2] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")


def drop_loocv(data: dict) -> None:
    data["loocv"] = {}


def nan_reference_tip(data: dict) -> None:
    data["reference_tips_m"]["rtip1"] = ["x", 0, 0]


def copy_session_without_last_sample(tmp: Path) -> None:
    shutil.copytree(GOOD["session"], tmp / "session")
    path = tmp / "session" / "samples.csv"
    path.write_text("\n".join(path.read_text().splitlines()[:-1]) + "\n")


def recorded_inputs(data: dict) -> None:
    data["inputs"] = {"samples.csv": "0" * 64}


GOOD: dict[str, str] = {}
SESSION = ["--calibration-session", "{session}"]

CASES = [
    Case("no-arguments", ["verify"], ("RESULT", "CHECK_SESSION")),
    Case("no-out", ["verify", "{result}", "{check}"], ("--out",)),
    Case("missing-result", ["verify", "{tmp}/nowhere.json", "{check}", *OUT], ("nowhere.json",)),
    Case("missing-check-session", ["verify", "{result}", "{tmp}/nowhere", *OUT], ("nowhere",)),
    Case(
        "check-without-samples",
        ["verify", "{result}", "{tmp}/check", *OUT],
        ("samples.csv", "missing"),
        copy_check(drop="samples.csv"),
    ),
    Case(
        "sample-not-a-number",
        ["verify", "{result}", "{tmp}/check", *OUT],
        ("samples.csv", "row 3", "v_px"),
        copy_check(bad_sample_value),
    ),
    Case(
        "touch-of-an-unknown-tool",
        ["verify", "{result}", "{tmp}/check", *OUT],
        ("touches.csv", "tool"),
        copy_check(replace_in("touches.csv", "\nprobe,", "\nscalpel,")),
    ),
    Case(
        "other-image-spacing",
        ["verify", "{result}", "{tmp}/check", *OUT],
        ("session.toml", "image.spacing_mm", "scanner setting"),
        copy_check(replace_in("session.toml", "spacing_mm = [0.19", "spacing_mm = [0.25")),
    ),
    Case(
        "result-without-loocv",
        ["verify", "{tmp}/result.json", "{check}", *OUT],
        ("result.json", "loocv.chain.rmse_mm"),
        copy_result(drop_loocv),
    ),
    Case(
        "result-reference-tip-not-numbers",
        ["verify", "{tmp}/result.json", "{check}", *OUT],
        ("result.json", "reference_tips_m.rtip1"),
        copy_result(nan_reference_tip),
    ),
    Case("method-not-in-result", ["verify", "{result}", "{check}", "--method", "kabsch", *OUT], ("kabsch",)),
    Case("false-alarm-zero", ["verify", "{result}", "{check}", "--false-alarm", "0", *OUT], ("--false-alarm",)),
    Case("false-alarm-too-big", ["verify", "{result}", "{check}", "--false-alarm", "0.7", *OUT], ("--false-alarm",)),
    Case("false-alarm-nan", ["verify", "{result}", "{check}", "--false-alarm", "nan", *OUT], ("--false-alarm",)),
    Case("result-of-another-robot", ["verify", "{result}", "{check}", "--robot", "baxter", *OUT], ("baxter",)),
    Case("demo-with-result", ["verify", "{result}", "--demo", "{tmp}/demo"], ("--demo",)),
    Case(
        "update-is-the-record",
        ["verify", "{result}", "{check}", *OUT, "--update", "{tmp}/record.json"],
        ("--update", "--out", "same file"),
    ),
    Case(
        "update-exists",
        ["verify", "{result}", "{check}", *OUT, "--update", "{tmp}/updated.json"],
        ("updated.json", "--force"),
        lambda tmp: (tmp / "updated.json").write_text("{}"),
    ),
    Case(
        "update-is-a-folder",
        ["verify", "{result}", "{check}", *OUT, "--update", "{tmp}/folder"],
        ("folder",),
        lambda tmp: (tmp / "folder").mkdir(),
    ),
    Case("demo-with-update", ["verify", "--update", "{tmp}/u.json", "--demo", "{tmp}/demo"], ("--demo", "--update")),
    Case("demo-with-calibration-session", ["verify", *SESSION, "--demo", "{tmp}/demo"], ("--demo",)),
    Case(
        "calibration-session-missing",
        ["verify", "{result}", "{check}", "--calibration-session", "{tmp}/nowhere", *OUT],
        ("nowhere",),
    ),
    Case(
        "calibration-session-of-other-samples",
        ["verify", "{result}", "{check}", "--calibration-session", "{tmp}/session", *OUT],
        ("samples.csv", "not the session this result was calibrated from"),
        copy_session_without_last_sample,
    ),
    Case(
        "calibration-session-files-differ-from-the-results-inputs",
        ["verify", "{tmp}/result.json", "{check}", *SESSION, *OUT],
        ("samples.csv", "SHA-256"),
        copy_result(recorded_inputs),
    ),
    Case("poses-without-check", ["plan", "--out", "{tmp}/p.csv", "--poses", "6"], ("--poses",)),
    Case("check-poses-too-few", ["plan", "check", "--out", "{tmp}/p.csv", "--poses", "2"], ("--poses",)),
    Case(
        "verify-and-excitation",
        ["plan", "check", "--excitation", "{check}", "--out", "{tmp}/p.csv"],
        ("--excitation",),
    ),
    Case("check-with-figure", ["plan", "check", "--figure", "{tmp}/f.png", "--out", "{tmp}/p.csv"], ("--figure",)),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, str]:
    """The demo's result and unchanged check session, outside the cases' folders."""
    folder = tmp_path_factory.mktemp("inputs") / "demo"
    outcome = run_cli(["verify", "--demo", str(folder)])
    assert outcome.code == 0, outcome.err
    # it says what to run next, on what it wrote
    assert f"\nnext: brachycal verify {folder / 'result.json'} {folder / 'check_unchanged'}" in outcome.out
    GOOD.update(
        result=str(folder / "result.json"), check=str(folder / "check_unchanged"), session=str(folder / "session")
    )
    return dict(GOOD)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_verify_refusals(case, tmp_path, inputs):
    check_refusal(case, tmp_path, **inputs)


def test_an_existing_record_is_not_replaced_without_force(inputs, tmp_path):
    record = tmp_path / "record.json"
    record.write_text("{}")
    outcome = run_cli(["verify", inputs["result"], inputs["check"], "--out", str(record)])
    assert outcome.code == 2 and "record.json" in outcome.err
    assert record.read_text() == "{}"
