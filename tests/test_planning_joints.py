"""Planning's pieces beyond the SDA10F: configurations reach Pinocchio in Pinocchio's own form, and
the plan's figure, drawn by a second process, fails as every command fails (one line, nothing written).

The SDA10F's coordinates are Pinocchio's configuration as they are; a robot with a continuous joint
(one angle for brachycal, ``(cos, sin)`` for Pinocchio) is where passing them on unchanged broke.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT
from hostile import Case, check_refusal

from brachycal.errors import InputError
from brachycal.model import ClearanceChecker, Robot, solve_ik

MESHES = ROOT / "urdf"


def two_links(first: str) -> Robot:
    """Two SDA10F collision meshes, the second swinging about z (0.3 m out, 0.6 m away) on joint ``turn``
    of type ``first``, then a revolute ``bend`` and a ``tip``."""
    limit = '<limit lower="-4" upper="4" effort="1" velocity="2"/>' if first != "continuous" else ""
    urdf = f"""<robot name="r">
  <link name="a"><collision><geometry><mesh filename="meshes/collision/base.stl"/></geometry></collision></link>
  <link name="b"><collision><origin xyz="0.3 0 0"/>
    <geometry><mesh filename="meshes/collision/link_t.stl"/></geometry></collision></link>
  <link name="c"/><link name="tip"/>
  <joint name="turn" type="{first}"><parent link="a"/><child link="b"/><origin xyz="0.6 0 0"/><axis xyz="0 0 1"/>
    {limit}</joint>
  <joint name="bend" type="revolute"><parent link="b"/><child link="c"/><axis xyz="1 0 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="2"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="c"/><child link="tip"/><origin xyz="0.2 0.1 0"/></joint>
</robot>"""
    return Robot(urdf, base_dir=MESHES)


def test_clearance_of_a_continuous_joint_is_that_of_the_same_angle_on_a_revolute_one():
    wheel, hinge = two_links("continuous"), two_links("revolute")
    assert wheel.model.nq == 3 and wheel.nq == 2  # (cos, sin) for Pinocchio, one angle here
    on_wheel = ClearanceChecker(wheel, [("a", "b")])
    on_hinge = ClearanceChecker(hinge, [("a", "b")])
    for angle in (-2.0, 0.4, 3.0):
        q = np.array([angle, 0.2])
        # Same geometry, same angle: the distances agree, and a full turn later they are the same
        # again, to Coal's own precision (its GJK stops within ~1e-8 m; 1e-6 m is a thousandth of
        # the smallest clearance margin a plan may use, 1 mm).
        assert on_wheel.distances(q) == pytest.approx(on_hinge.distances(q), abs=1e-6)
        assert on_wheel.distances(q + np.array([2 * np.pi, 0])) == pytest.approx(on_wheel.distances(q), abs=1e-6)
    assert on_wheel.distances([0.0, 0.2])[0] != pytest.approx(on_wheel.distances([1.5, 0.2])[0], abs=1e-2)  # it swings


def test_ik_places_a_tip_turned_by_a_continuous_joint_past_a_full_turn():
    wheel = two_links("continuous")
    goal = wheel.fk("tip", np.array([7.0, 0.3]))  # more than a turn: no limit to hold it
    q = solve_ik(wheel, "tip", goal, np.array([6.6, 0.1]), [0, 1], position_only=True)
    # The solver's tolerance is 1e-12 (metres); 1e-10 leaves room for the last step's rounding.
    assert np.linalg.norm(wheel.fk("tip", q)[:3, 3] - goal[:3, 3]) < 1e-10


def test_ik_refuses_to_move_a_coordinate_of_a_floating_joint():
    floating = two_links("floating")
    with pytest.raises(InputError, match="revolute, prismatic and continuous joints only"):
        solve_ik(floating, "tip", floating.fk("tip", np.zeros(floating.nq)), np.zeros(floating.nq), [0])


def test_a_figure_the_drawing_process_cannot_draw_is_refused_in_one_line_with_nothing_written(tmp_path, capfd):
    # The figure is drawn by a second process; matplotlib there refuses the format. Before, the same
    # refusal in-process was a traceback.
    case = Case(
        "plan-figure-format-unknown",
        ["plan", "--out", "{tmp}/p.csv", "--points", "2", "--allow-partial", "--figure", "{tmp}/p.xyz", "--quiet"],
        ("p.xyz", "could not draw the figure", "format 'xyz' is not supported"),
    )
    check_refusal(case, tmp_path)
    assert capfd.readouterr().err == ""  # the drawing process printed nothing of its own
