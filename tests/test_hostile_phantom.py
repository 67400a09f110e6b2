"""Hostile input to ``brachycal phantom``: malformed or ill-posed phantom geometries and observation
files, each refused in one line naming the file (and row and column where there is one), exit code
2, nothing written. Every observations case starts from a valid exact session of the bundled phantom
(written by :func:`brachycal.calibration.write_phantom_observations`) changed in one way.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from pathlib import Path

import pytest
from hostile import Case, check_refusal
from test_wedge_phantom import exact_session as wedge_session
from test_wire_phantom import exact_session as wire_session

from brachycal.calibration import read_wedge_phantom, read_wire_phantom, write_phantom_observations
from brachycal.io import bundled

WIRE = ["phantom", "wire", "{tmp}/geometry.toml", "{tmp}/obs.csv", "--out", "{tmp}/out.json"]
WEDGE = ["phantom", "wedge", "{tmp}/geometry.toml", "{tmp}/obs.csv", "--out", "{tmp}/out.json"]


@cache
def valid_text(kind: str, frames: int) -> tuple[str, str]:
    """(geometry TOML, observations CSV) of a valid exact session of the bundled phantom."""
    import tempfile

    if kind == "wire":
        phantom, seen = read_wire_phantom(), None
        seen = wire_session(phantom, frames)
        geometry = bundled("phantoms", "arbitrary_wire.toml").read_text()
    else:
        phantom = read_wedge_phantom()
        seen = wedge_session(phantom, frames)
        geometry = bundled("phantoms", "multi_wedge.toml").read_text()
    with tempfile.TemporaryDirectory() as tmp:
        path = write_phantom_observations(Path(tmp) / "obs.csv", "multi-wedge" if kind == "wedge" else "wire", seen)
        return geometry, path.read_text()


def files(
    kind: str = "wire",
    geometry: Callable[[str], str] = lambda text: text,
    observations: Callable[[str], str] = lambda text: text,
    frames: int = 12,
) -> Callable[[Path], None]:
    """Write ``{tmp}/geometry.toml`` and ``{tmp}/obs.csv`` of a valid session, each changed by its function."""

    def setup(tmp: Path) -> None:
        g, o = valid_text(kind, frames)
        (tmp / "geometry.toml").write_text(geometry(g))
        (tmp / "obs.csv").write_text(observations(o))

    return setup


def row(k: int, change: Callable[[list[str]], list[str]]) -> Callable[[str], str]:
    """Change the fields of data row ``k`` (0 = first after the header)."""

    def edit(text: str) -> str:
        lines = text.splitlines()
        lines[k + 1] = ",".join(change(lines[k + 1].split(",")))
        return "\n".join(lines) + "\n"

    return edit


def set_field(column: int, value: str) -> Callable[[list[str]], list[str]]:
    return lambda fields: [*fields[:column], value, *fields[column + 1 :]]


def millimetres(text: str) -> str:
    """The observations with the tracker positions (``*_x``, ``*_y``, ``*_z``, metres) times 1000."""
    lines = text.splitlines()
    header = lines[0].split(",")
    columns = [k for k, name in enumerate(header) if name.endswith(("_x", "_y", "_z"))]
    out = [lines[0]]
    for line in lines[1:]:
        fields = line.split(",")
        for k in columns:
            fields[k] = repr(float(fields[k]) * 1e3)
        out.append(",".join(fields))
    return "\n".join(out) + "\n"


ONE_WEDGE = """format = "brachycal-phantom/1"
kind = "multi-wedge"
[[wedge]]
name = "A"
[[wedge.face]]
name = "A1"
point_mm = [0, 0, 0]
normal = [-0.5, 0.1, 0.866]
[[wedge.face]]
name = "A2"
point_mm = [0, 0, 0]
normal = [0.5, 0.1, 0.866]
"""
PARALLEL = 'format = "brachycal-phantom/1"\nkind = "wire"\n' + "".join(
    f'[[wire]]\nname = "W{k}"\nfrom_mm = [{x}, -30, -20]\nto_mm = [{x}, 30, -20]\n' for k, x in enumerate((-20, 0, 20))
)

CASES = [
    Case("unknown phantom kind", ["phantom", "cube", *WIRE[2:]], ("invalid choice", "cube"), files()),
    Case("no phantom kind", ["phantom", *WIRE[2:]], ("KIND", "invalid choice", "wedge"), files()),
    Case(
        "earlier spelling, unknown kind",
        ["phantom", "--method", "cube", *WIRE[2:]],
        ("invalid choice", "cube"),
        files(),
    ),
    Case("a kind and --method", [*WIRE, "--method", "wedge"], ("unrecognized arguments", "--method"), files()),
    Case("missing geometry", WIRE, ("geometry.toml", "no such file"), lambda tmp: None),
    Case("geometry not TOML", WIRE, ("geometry.toml", "TOML"), files(geometry=lambda t: t + "\n[[[")),
    Case(
        "geometry of another format", WIRE, ("format",), files(geometry=lambda t: t.replace("phantom/1", "phantom/9"))
    ),
    Case("wire geometry for the wedge phantom", WEDGE, ("not a 'multi-wedge'",), files()),
    Case(
        "geometry without the phantom's registration",
        WIRE,
        ("geometry.toml", "no T_reference_phantom_mm", "registration"),
        files(geometry=lambda t: "\n".join(x for x in t.splitlines() if not x.startswith("T_reference_phantom_mm"))),
    ),
    Case("one wedge", WEDGE, ("1 wedge", "one wedge"), files("wedge", geometry=lambda t: ONE_WEDGE)),
    Case("parallel wires", WIRE, ("parallel",), files(geometry=lambda t: PARALLEL)),
    Case(
        "wire of zero length",
        WIRE,
        ("W1", "zero length"),
        files(geometry=lambda t: t.replace("to_mm = [-18.75, 30.0, -30.0]", "to_mm = [-30.0, -30.0, -20.0]")),
    ),
    Case(
        "face without a normal",
        WEDGE,
        ("A1", "zero normal"),
        files("wedge", geometry=lambda t: t.replace("normal = [-0.433012701892", "normal = [0.0, 0.0, 0.0] #", 1)),
    ),
    Case(
        "observations without a column",
        WIRE,
        ("obs.csv", "v_px"),
        files(observations=lambda t: t.replace(",v_px", ",w_px", 1)),
    ),
    Case("only a header", WIRE, ("obs.csv", "no observations"), files(observations=lambda t: t.splitlines()[0] + "\n")),
    Case("unknown wire", WIRE, ("row 2", "feature", "W9"), files(observations=row(0, set_field(1, "W9")))),
    Case("a wire twice in a frame", WIRE, ("row 3", "twice"), files(observations=row(1, set_field(1, "W1")))),
    Case(
        "text for a pixel", WIRE, ("row 4", "u_px", "not a number"), files(observations=row(2, set_field(16, "12.5x")))
    ),
    Case("NaN pixel", WIRE, ("row 2", "v_px", "finite"), files(observations=row(0, set_field(17, "nan")))),
    # Numbers that parse but are wrong: digit separators, absurd magnitudes, another unit, a cut file.
    Case(
        "pixel with a digit separator",
        WIRE,
        ("row 2", "u_px", "'1_2.5' is not a number"),
        files(observations=row(0, set_field(16, "1_2.5"))),
    ),
    Case(
        "probe coordinate 1e308",
        WIRE,
        ("row 3", "probe_x", "1e+308 m", "not a physical position"),
        files(observations=row(1, set_field(2, "1e308"))),
    ),
    Case(
        "pixel 1e308",
        WIRE,
        ("row 2", "v_px", "1e+308 px", "not a physical position"),
        files(observations=row(0, set_field(17, "1e308"))),
    ),
    Case(
        "observations in millimetres",
        WIRE,
        ("row 2", "probe_x", "m is beyond ±10 m", "another unit"),
        files(observations=lambda t: millimetres(t)),
    ),
    Case(
        "observations cut mid-number",
        WIRE,
        ("obs.csv, row", "the last line has no newline"),
        files(observations=lambda t: t.rstrip("\n")[:-3]),
    ),
    Case(
        "wire end 1e308",
        WIRE,
        ("geometry.toml", "from_mm", "1e+308 mm", "not a physical position"),
        files(geometry=lambda t: t.replace("from_mm = [-30.00, -30.0, -20.0]", "from_mm = [1e308, -30.0, -20.0]")),
    ),
    Case(
        "registration translation 1e308",
        WIRE,
        ("geometry.toml", "T_reference_phantom_mm translation", "not a physical position"),
        files(geometry=lambda t: t.replace("[1.0, 0.0, 0.0, 0.0], [0.0", "[1.0, 0.0, 0.0, 1e308], [0.0", 1)),
    ),
    Case(
        "quaternion not a unit one",
        WIRE,
        ("row 2", "probe_qw", "quaternion"),
        files(observations=row(0, set_field(8, "3"))),
    ),
    Case("one frame, two tracker readings", WIRE, ("row 3", "differ"), files(observations=row(1, set_field(2, "0.5")))),
    Case("too few frames", WIRE, ("frame", "at least 3"), files(frames=2)),
    Case("table3 with the committed example", ["demo", "--table3", "--example"], ("--table3", "--example")),
    Case("table3 with a recording", ["demo", "--table3", "--recording", "--out", "{tmp}/d"], ("--recording",)),
    Case("seeds without table3", ["demo", "--seeds", "3", "--out", "{tmp}/d"], ("--seeds", "--table3")),
    Case("no seeds", ["demo", "--table3", "--seeds", "0"], ("--seeds",)),
    Case(
        "a wedge line of one pixel",
        WEDGE,
        ("row 2", "same pixel"),
        files("wedge", observations=row(0, lambda f: [*f[:18], f[16], f[17]])),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_phantom_refuses(case: Case, tmp_path: Path) -> None:
    check_refusal(case, tmp_path)
