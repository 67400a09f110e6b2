"""A session's imaging sector (``[image.sector]`` of ``session.toml``) is checked against its samples.

A sector is where the image shows tissue: an annotated needle tip lies inside it. A sector that holds
none of the session's tips is misstated (its apex, depth or angle) and is refused in one line naming
``session.toml`` and the key; one that leaves some tips out (beyond a millimetre: annotation noise
and rounded figures) is read with a warning naming the farthest. The refusals of ``session.toml``
name its keys as keys, and a number beyond the float range is refused, not a traceback.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import ROOT
from hostile import Case, check_refusal

from brachycal import InputError
from brachycal.data.session import read_session
from brachycal.errors import BrachycalWarning

SESSION = ROOT / "examples" / "session_exact"  # 64 tips at u 324..810, v 108..612 px, 0.19 mm/px


def with_sector(text: str) -> Callable[[Path], None]:
    """Copy the example session into ``tmp/s`` with ``text`` as its ``[image.sector]``."""

    def setup(tmp: Path) -> None:
        shutil.copytree(SESSION, tmp / "s")
        toml = tmp / "s" / "session.toml"
        toml.write_text(toml.read_text().replace("[top_model]", f"[image.sector]\n{text}\n\n[top_model]"))

    return setup


#: Holds every tip (5 mm inside at the nearest): apex 38 mm above the image's top centre, 200 mm deep, 90° open.
HOLDS_ALL = "apex_px = [540, -200]\ndepth_mm = 200\nangle_deg = 90"
#: Its apex's u off by the image's width: every tip lies far outside.
HOLDS_NONE = "apex_px = [1620, -20.5]\ndepth_mm = 140\nangle_deg = 60"
#: 140 mm deep: the deepest row of 16 tips (v = 612 px, 154-163 mm from the apex) lies outside, the
#: next (v = 444 px, at most 132 mm) inside.
HOLDS_SOME = "apex_px = [540, -200]\ndepth_mm = 140\nangle_deg = 90"
CALIBRATE = ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--quiet"]


def test_a_sector_that_holds_every_tip_is_read_without_a_word(tmp_path, robot, recwarn):
    with_sector(HOLDS_ALL)(tmp_path)
    assert read_session(tmp_path / "s", robot).sector is not None
    assert not [w for w in recwarn if issubclass(w.category, BrachycalWarning)]


def test_a_sector_that_holds_none_of_the_tips_is_refused_naming_the_file_and_key(tmp_path, robot):
    with_sector(HOLDS_NONE)(tmp_path)
    with pytest.raises(InputError, match="holds none of the 64") as refused:
        read_session(tmp_path / "s", robot)
    assert refused.value.file == str(tmp_path / "s" / "session.toml") and refused.value.key == "image.sector"


def test_a_sector_that_leaves_some_tips_out_is_read_with_a_warning_naming_the_farthest(tmp_path, robot):
    with_sector(HOLDS_SOME)(tmp_path)
    with pytest.warns(BrachycalWarning, match=r"16 of 64 annotated needle tips lie outside .*\[image.sector\]"):
        session = read_session(tmp_path / "s", robot)
    assert session.sector is not None and session.sector.depth_m == pytest.approx(0.14, rel=1e-15)


CASES = [
    Case(
        "sector-holds-no-tip",
        CALIBRATE,
        ("session.toml", "key 'image.sector'", "none of the 64", "apex_px, depth_mm or angle_deg"),
        with_sector(HOLDS_NONE),
    ),
    Case(  # was a traceback (OverflowError): TOML's integers are unbounded
        "sector-apex-401-digits",
        CALIBRATE,
        ("session.toml", "key 'image.sector.apex_px'", "finite numbers"),
        with_sector(f"apex_px = [{'9' * 401}, 0]\ndepth_mm = 70\nangle_deg = 120"),
    ),
    Case(
        "sector-depth-401-digits",
        CALIBRATE,
        ("session.toml", "key 'image.sector.depth_mm'", "finite numbers"),
        with_sector(f"apex_px = [540, 0]\ndepth_mm = -{'9' * 401}\nangle_deg = 120"),
    ),
    Case(
        "spacing-401-digits",
        CALIBRATE,
        ("session.toml", "key 'image.spacing_mm'", "finite numbers"),
        lambda tmp: (
            shutil.copytree(SESSION, tmp / "s"),
            (tmp / "s" / "session.toml").write_text(
                (SESSION / "session.toml").read_text().replace("[0.19, 0.19]", f"[0.19, {'9' * 401}]")
            ),
        ),
    ),
    Case(
        "sector-angle-beyond-180",  # a range refusal of a key, named as a key
        CALIBRATE,
        ("session.toml", "key 'image.sector.angle_deg'", "(0, 180] deg"),
        with_sector("apex_px = [540, 0]\ndepth_mm = 70\nangle_deg = 200"),
    ),
]


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_a_misstated_session_toml_is_refused_in_one_line_naming_its_key(case, tmp_path):
    check_refusal(case, tmp_path)
