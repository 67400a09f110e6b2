"""Hostile parameters: every numeric option of every sub-command, given NaN, infinity or a value out
of its range, is refused before any work with one line naming the option, exit code 2, nothing
written (``hostile.check_refusal``).

The known failures come first (negative margins that would plan poses past the joint limits,
NaN switching checks off, a zero spacing writing infinite pixels, a typo exhausting memory), then
one NaN, one infinity and one out-of-range case per numeric option, and last the spacings and
image sizes that reach a command through its input files (a result, a session). Each refusal
comes from argparse or from the first lines of the command, so every case takes milliseconds;
nothing here plans or simulates, and the one calibration is the module's fixture.
"""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli

SESSION = ROOT / "examples" / "session_exact"
JOINTS = ROOT / "examples" / "joint_log.csv"

DEMO = ["demo", "--out", "{tmp}/demo"]
PLAN = ["plan", "--out", "{tmp}/plan.csv", "--quiet"]
CALIBRATE = ["calibrate", str(SESSION), "--out", "{tmp}/result.json", "--quiet"]
LOCATE = ["locate", "{result}", str(JOINTS)]
STUDY = ["study", "--out", "{tmp}/study", "--quiet"]
DESIGN = ["design", "--out", "{tmp}/design", "--quiet"]
TEMPLATE = ["stepper", "template", "{result}", "--config", "{tmp}/config.xml", "--hole", "D4", "--probe-position=0"]


def numeric(command: list[str], option: str, cases: dict[str, tuple[str, tuple[str, ...]]]) -> list[Case]:
    """One case per ``name -> (value, expected words)`` of ``option``; the option is always named.

    Values go as ``--option=value`` so that a negative number is not taken for an option.
    """
    return [
        Case(f"{command[0]}{option}-{name}", [*command, f"{option}={value}"], (option, *words))
        for name, (value, words) in cases.items()
    ]


NAN = ("nan", ("finite",))
INF = ("inf", ("finite",))
MINUS_INF = ("-inf", ("finite",))

CASES = [
    # --- the known failures -------------------------------------------------------------------------
    Case(
        "plan-negative-margins",
        [*PLAN, "--joint-margin-deg=-20", "--collision-margin-mm=-500"],
        ("--joint-margin-deg", "in [0.1, 45] deg", "-20"),
    ),
    Case("plan-nan-collision-margin", [*PLAN, "--collision-margin-mm", "nan"], ("--collision-margin-mm", "finite")),
    Case("plan-nan-sector-depth", [*PLAN, "--sector-depth-mm", "nan"], ("--sector-depth-mm", "finite")),
    Case("plan-zero-spacing", [*PLAN, "--spacing-mm", "0,0"], ("--spacing-mm", "positive")),
    Case(
        "plan-spacing-in-metres-typed-as-mm",
        [*PLAN, "--spacing-mm", "1.9e-4,1.9e-4"],
        ("--spacing-mm", "metres typed as millimetres", "0.19"),
    ),
    Case("plan-points-exhaust-memory", [*PLAN, "--points", "1000"], ("--points", "in [2, 20]")),
    Case("locate-u-outside-the-image", [*LOCATE, "--uv", "1080,300"], ("--uv", "outside", "1080 x 720")),
    Case("locate-v-outside-the-image", [*LOCATE, "--uv", "540,720"], ("--uv", "outside", "719.5")),
    Case("locate-negative-pixel", [*LOCATE, "--uv=-3,300"], ("--uv", "in [-0.5, 10000] px")),
    Case("study-outlier-rate-above-one", [*STUDY, "--outlier-rate", "1.5"], ("--outlier-rate", "in [0, 0.5]")),
    Case("demo-negative-seed", [*DEMO, "--seed=-1"], ("--seed", "[0, 2**32)")),
    Case("demo-no-targets", [*DEMO, "--targets", "0"], ("--targets", "in [1, 100000]")),
    Case("study-negative-workers", [*STUDY, "--workers=-1"], ("--workers", "in [1, 256]")),
    # --- numbers that Python's float/int take but no writer writes ----------------------------------
    Case("demo-seed-digit-separator", [*DEMO, "--seed", "4_2"], ("--seed", "a whole number", "'4_2'")),
    Case("demo-seed-arabic-indic", [*DEMO, "--seed", "\u0664\u0662"], ("--seed", "a whole number")),
    Case("demo-targets-hexadecimal", [*DEMO, "--targets", "0x10"], ("--targets", "a whole number", "'0x10'")),
    Case(
        "plan-margin-digit-separator",
        [*PLAN, "--collision-margin-mm", "2_5"],
        ("--collision-margin-mm", "a number", "'2_5'"),
    ),
    Case("plan-spacing-infinity", [*PLAN, "--spacing-mm", "0.19,infinity"], ("--spacing-mm", "'infinity'")),
    Case("locate-uv-digit-separator", [*LOCATE, "--uv", "5_40,300"], ("--uv", "value 1", "'5_40'")),
    # --- demo ---------------------------------------------------------------------------------------
    *numeric(
        DEMO,
        "--seed",
        {"nan": ("nan", ("whole number",)), "fraction": ("1.5", ("whole",)), "big": ("4294967296", ("2**32",))},
    ),
    *numeric(
        DEMO,
        "--targets",
        {"nan": ("nan", ("whole number",)), "inf": ("inf", ("whole number",)), "many": ("100001", ("100000",))},
    ),
    # --- plan: grid --------------------------------------------------------------------------------
    *numeric(
        PLAN,
        "--centre-mm",
        {
            "nan": ("800,nan,1050", ("value 2", "finite")),
            "inf": ("inf,100,1050", ("finite",)),
            "beyond-reach": ("800,100,9000", ("[-5000, 5000] mm",)),
            "count": ("800,100", ("3 comma-separated",)),
        },
    ),
    *numeric(
        PLAN, "--edge-mm", {"nan": NAN, "inf": INF, "zero": ("0", ("[1, 500] mm",)), "huge": ("4000", ("[1, 500] mm",))}
    ),
    *numeric(
        PLAN,
        "--points",
        {
            "nan": ("nan", ("whole number",)),
            "inf": ("inf", ("whole number",)),
            "one": ("1", ("[2, 20]",)),
            "fraction": ("4.5", ("whole number",)),
        },
    ),
    *numeric(
        PLAN,
        "--insertion",
        {"nan": ("1,nan,0", ("finite",)), "inf": ("inf,0,0", ("finite",)), "zero": ("0,0,0", ("zero vector",))},
    ),
    # --- plan: imaging ------------------------------------------------------------------------------
    *numeric(
        PLAN,
        "--image-depth",
        {"nan": ("nan,0,0", ("finite",)), "inf": ("0,-inf,0", ("finite",)), "zero": ("0,0,0", ("zero vector",))},
    ),
    *numeric(
        PLAN,
        "--image-lateral",
        {"nan": ("0,0,nan", ("finite",)), "inf": ("0,0,inf", ("finite",)), "zero": ("0,0,0", ("zero vector",))},
    ),
    Case(
        "plan-parallel-image-axes",
        [*PLAN, "--image-depth", "1,0,0", "--image-lateral=-2,0,0"],
        ("--image-depth", "--image-lateral", "parallel"),
    ),
    *numeric(
        PLAN,
        "--centre-px",
        {"nan": ("nan,221", ("finite",)), "inf": ("540,inf", ("finite",)), "far": ("540,20000", ("[-0.5, 10000] px",))},
    ),
    *numeric(
        PLAN,
        "--spacing-mm",
        {
            "nan": ("0.19,nan", ("finite",)),
            "inf": ("inf,0.19", ("finite",)),
            "negative": ("-0.19,0.19", ("positive",)),
            "huge": ("190,190", ("[0.005, 2] mm/px",)),
        },
    ),
    *numeric(
        PLAN,
        "--sector-apex-px",
        {
            "nan": ("nan,0", ("finite",)),
            "inf": ("540,-inf", ("finite",)),
            "far": ("540,-20000", ("[-10000, 10000] px",)),
        },
    ),
    *numeric(
        PLAN,
        "--sector-depth-mm",
        {"nan": NAN, "inf": INF, "zero": ("0", ("(0, 500] mm",)), "deep": ("600", ("(0, 500] mm",))},
    ),
    *numeric(
        PLAN,
        "--sector-angle-deg",
        {"nan": NAN, "inf": INF, "zero": ("0", ("(0, 180] deg",)), "wide": ("200", ("(0, 180] deg",))},
    ),
    *numeric(
        [*PLAN, "--fov", "rect"],
        "--rect-px",
        {
            "nan": ("0,nan,0,719", ("finite",)),
            "inf": ("0,1079,0,inf", ("finite",)),
            "negative": ("-5,1079,0,719", ("[-0.5, 10000] px",)),
        },
    ),
    Case("plan-rect-upside-down", [*PLAN, "--fov", "rect", "--rect-px", "0,1079,719,0"], ("--rect-px", "V0 < V1")),
    # --- plan: tools and safety ---------------------------------------------------------------------
    *numeric(
        PLAN,
        "--collision-margin-mm",
        {"inf": INF, "negative": ("-500", ("[1, 100] mm",)), "below-floor": ("0.5", ("[1, 100] mm",))},
    ),
    *numeric(
        PLAN,
        "--joint-margin-deg",
        {"nan": NAN, "inf": MINUS_INF, "zero": ("0", ("[0.1, 45] deg",)), "wide": ("50", ("[0.1, 45] deg",))},
    ),
    *numeric(
        PLAN,
        "--speed-scale",
        {"nan": NAN, "inf": INF, "zero": ("0", ("(0, 1]",)), "faster-than-vendor": ("1.5", ("(0, 1]",))},
    ),
    Case("plan-unknown-method", [*PLAN, "--method", "icpp"], ("--method", "invalid choice")),
    # --- calibrate ----------------------------------------------------------------------------------
    *numeric(
        [*CALIBRATE, "--solve", "chain"],
        "--bootstrap",
        {
            "nan": ("nan", ("whole number",)),
            "inf": ("inf", ("whole number",)),
            "negative": ("-1", ("[0, 10000]",)),
            "many": ("10001", ("[0, 10000]",)),
        },
    ),
    Case("calibrate-bootstrap-without-chain", [*CALIBRATE, "--bootstrap", "100"], ("--bootstrap", "--solve chain")),
    Case(
        "calibrate-joint-offsets-without-chain", [*CALIBRATE, "--joint-offsets"], ("--joint-offsets", "--solve chain")
    ),
    Case(
        "calibrate-identify-robot-without-chain",
        [*CALIBRATE, "--identify-robot"],
        ("--identify-robot", "--solve chain"),
    ),
    Case(
        "calibrate-identify-robot-and-joint-offsets",
        [*CALIBRATE, "--solve", "chain", "--identify-robot", "--joint-offsets"],
        ("--identify-robot", "--joint-offsets"),
    ),
    # --method is an image method's name (locate, export); calibrate's earlier --method chain is --solve.
    Case("calibrate-method-an-image-method", [*CALIBRATE, "--method", "kabsch"], ("--method", "--methods kabsch")),
    Case(
        "calibrate-method-chain-robot",
        [*CALIBRATE, "--method", "chain+robot"],
        ("--method", "--solve chain --identify-robot"),
    ),
    Case("calibrate-method-unknown", [*CALIBRATE, "--method", "magic"], ("--method", "'magic'", "icp")),
    Case("calibrate-solve-unknown", [*CALIBRATE, "--solve", "kabsch"], ("--solve", "invalid choice")),
    Case(
        "calibrate-solve-and-old-method-disagree",
        [*CALIBRATE, "--solve", "sequential", "--method", "chain"],
        ("--solve sequential", "--method chain"),
    ),
    Case("calibrate-unknown-method", [*CALIBRATE, "--methods", "kabsch,icpp"], ("--methods", "'icpp'")),
    Case("calibrate-empty-method", [*CALIBRATE, "--methods", "kabsch,,horn"], ("--methods", "empty")),
    Case("calibrate-repeated-method", [*CALIBRATE, "--methods", "horn,horn"], ("--methods", "twice")),
    # --- locate, export, fk -------------------------------------------------------------------------
    *numeric(
        LOCATE,
        "--uv",
        {"nan": ("nan,300", ("finite",)), "inf": ("540,inf", ("finite",)), "count": ("540", ("2 comma-separated",))},
    ),
    Case("locate-unknown-method", [*LOCATE, "--uv", "540,300", "--method", "icpp"], ("--method", "invalid choice")),
    Case(
        "export-unknown-method",
        ["export", "{result}", "--out", "{tmp}/x", "--method", "icpp"],
        ("--method", "invalid choice"),
    ),
    Case(
        "fk-empty-frame", ["fk", str(JOINTS), "--frames", "needle_tip,", "--out", "{tmp}/p.csv"], ("--frames", "empty")
    ),
    Case(
        "fk-repeated-frame",
        ["fk", str(JOINTS), "--frames", "probe_tip,probe_tip", "--out", "{tmp}/p.csv"],
        ("--frames", "twice"),
    ),
    # --- study --------------------------------------------------------------------------------------
    *numeric(
        STUDY,
        "--seeds",
        {
            "nan": ("nan", ("whole number",)),
            "inf": ("inf", ("whole number",)),
            "zero": ("0", ("[1, 1000]",)),
            "many": ("1001", ("[1, 1000]",)),
        },
    ),
    *numeric(
        STUDY,
        "--points",
        {
            "nan": ("4,nan", ("whole number",)),
            "inf": ("inf", ("whole number",)),
            "one": ("1,4", ("value 1", "[2, 20]")),
            "many": ("4,21", ("value 2", "[2, 20]")),
        },
    ),
    *numeric(STUDY, "--edge-mm", {"nan": NAN, "inf": INF, "zero": ("40,0", ("value 2", "[1, 500] mm"))}),
    *numeric(
        STUDY,
        "--annotation-px",
        {"nan": NAN, "inf": INF, "negative": ("-1", ("[0, 50] px",)), "huge": ("51", ("[0, 50] px",))},
    ),
    *numeric(STUDY, "--outlier-rate", {"nan": NAN, "inf": INF, "negative": ("-0.1", ("[0, 0.5]",))}),
    *numeric(
        STUDY,
        "--targets",
        {"nan": ("nan", ("whole number",)), "inf": ("inf", ("whole number",)), "zero": ("0", ("[1, 100000]",))},
    ),
    *numeric(
        STUDY,
        "--workers",
        {
            "nan": ("nan", ("whole number",)),
            "inf": ("inf", ("whole number",)),
            "zero": ("0", ("[1, 256]",)),
            "many": ("257", ("[1, 256]",)),
        },
    ),
    Case("study-unknown-method", [*STUDY, "--methods", "kabsch,icpp"], ("--methods", "'icpp'")),
    Case("study-unknown-robot-error", [*STUDY, "--robot-error", "perfect"], ("--robot-error", "'perfect'")),
    Case(
        "study-sweep-too-large",
        [*STUDY, "--seeds", "1000", "--points", "2,3,4,5,6,7,8,9,10,11,12"],
        ("33000 simulated sessions", "at most 10000"),
    ),
    # --- design -------------------------------------------------------------------------------------
    *numeric(
        DESIGN,
        "--seeds",
        {
            "nan": ("nan", ("whole number",)),
            "inf": ("inf", ("whole number",)),
            "zero": ("0", ("[1, 1000]",)),
            "many": ("1001", ("[1, 1000]",)),
        },
    ),
    Case("design-unknown-design", [*DESIGN, "--designs", "grid 5x5x5"], ("--designs", "'grid 5x5x5'")),
    # --- stepper template: what a stepper and a 200 mm needle can reach (a rotation of 1e308 deg
    # was a "math domain error" traceback, a depth of nan printed np.float64(0.0)) ------------------
    *numeric(
        TEMPLATE,
        "--depth",
        {"nan": NAN, "inf": INF, "huge": ("1e6", ("[0, 300] mm",)), "negative": ("-5", ("[0, 300] mm",))},
    ),
    *numeric(
        TEMPLATE,
        "--probe-position",
        {"nan": NAN, "minus-inf": MINUS_INF, "huge": ("1e308", ("[-300, 300] mm",))},
    ),
    *numeric(
        TEMPLATE,
        "--probe-rotation",
        {"nan": NAN, "inf": INF, "huge": ("1e308", ("[-360, 360] deg",))},
    ),
    *numeric(
        TEMPLATE,
        "--template-position",
        {"nan": NAN, "inf": INF, "huge": ("-1e6", ("[-300, 300] mm",))},
    ),
]


@pytest.fixture(scope="module")
def result(tmp_path_factory) -> Path:
    """A result of the exact example session (Kabsch only: quick), outside the cases' folders."""
    path = tmp_path_factory.mktemp("inputs") / "result.json"
    outcome = run_cli(["calibrate", str(SESSION), "--out", str(path), "--methods", "kabsch", "--quiet"])
    assert outcome.code == 0, outcome.err
    return path


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_parameter_refusals(case, tmp_path, result):
    check_refusal(case, tmp_path, result=result)


def test_ids_are_unique():
    ids = [case.id for case in CASES]
    assert len(ids) == len(set(ids))


def test_locate_accepts_the_edges_of_the_image(result):
    # The bounds refused above are the image's own: its last pixel's far half is still inside.
    outcome = run_cli([*[str(a).format(result=result) for a in LOCATE], "--uv", "1079.5,719.5"])
    assert outcome.code == 0, outcome.err
    assert outcome.out.splitlines()[0] == "line,x_m,y_m,z_m"


def edited_result(result: Path, edit) -> Case:
    """A case's setup: ``{tmp}/result.json`` = the fixture's result with ``edit(payload)`` applied."""

    def setup(tmp: Path) -> None:
        payload = json.loads(result.read_text())
        edit(payload)
        (tmp / "result.json").write_text(json.dumps(payload))  # json.dumps writes Infinity as is

    return setup


@pytest.mark.parametrize(
    "name, edit, words",
    [
        ("infinite", lambda p: p["spacing_mm"].update(kabsch=[math.inf, 0.19]), ("spacing_mm.kabsch", "finite")),
        ("metres", lambda p: p["spacing_mm"].update(kabsch=[1.9e-4, 1.9e-4]), ("metres typed as millimetres",)),
        ("image-size", lambda p: p["image"].update(size_px=[1080.5, 720]), ("image.size_px", "whole numbers")),
    ],
)
def test_locate_refuses_a_result_with_an_implausible_spacing_or_image(name, edit, words, tmp_path, result):
    argv = ["locate", "{tmp}/result.json", str(JOINTS), "--uv", "540,300"]
    check_refusal(Case(f"locate-result-{name}", argv, words, edited_result(result, edit)), tmp_path)


def test_calibrate_refuses_a_session_spacing_in_metres(tmp_path):
    def setup(tmp: Path) -> None:
        shutil.copytree(SESSION, tmp / "session")
        toml = tmp / "session" / "session.toml"
        toml.write_text(re.sub(r"spacing_mm = \[[^]]*\]", "spacing_mm = [1.9e-4, 1.9e-4]", toml.read_text()))

    argv = ["calibrate", "{tmp}/session", "--out", "{tmp}/result.json", "--quiet"]
    words = ("session.toml", "image.spacing_mm", "metres typed as millimetres", "give 0.19")
    check_refusal(Case("calibrate-session-spacing-in-metres", argv, words, setup), tmp_path)
