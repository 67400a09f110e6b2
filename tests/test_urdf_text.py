"""URDF text editing: refusals of a tool joint that the text does not describe completely."""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.errors import InputError
from brachycal.model import urdf_text

URDF = """<robot name="r">
  <link name="flange"/><link name="tool"/>
  <joint name="tool_joint" type="fixed">{parent}<child link="tool"/><origin xyz="0.1 0 0" rpy="0 0 0"/></joint>
</robot>"""


def test_fixed_joint_transform_reads_parent_and_origin():
    root = urdf_text.parse(URDF.format(parent='<parent link="flange"/>'), "robot.urdf")
    parent, T_flange_tool = urdf_text.fixed_joint_transform(root, "tool", "robot.urdf")
    assert parent == "flange"
    assert np.array_equal(T_flange_tool[:3, 3], [0.1, 0.0, 0.0])  # "0.1" parsed, not computed: exact


@pytest.mark.parametrize("parent", ["", "<parent/>", '<parent link=""/>'], ids=["no element", "no link", "empty link"])
def test_fixed_joint_without_a_parent_link_is_one_input_error_naming_the_file(parent):
    root = urdf_text.parse(URDF.format(parent=parent), "robot.urdf")
    with pytest.raises(
        InputError, match=r"^robot\.urdf: the fixed joint 'tool_joint' ending at frame 'tool' has no parent link$"
    ):
        urdf_text.fixed_joint_transform(root, "tool", "robot.urdf")
