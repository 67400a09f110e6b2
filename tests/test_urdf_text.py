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


# A <transmission> names its joint with a <joint> element of its own; only <robot>'s direct
# <joint> children are the kinematic tree's joints.
TRANSMISSION_FIRST = """<robot name="r">
  <transmission name="t1"><type>SimpleTransmission</type>
    <joint name="j1"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>1</mechanicalReduction></actuator>
  </transmission>
  <link name="base"/><link name="l1"/><link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="tool_joint" type="fixed"><parent link="l1"/><child link="tool"/>
    <origin xyz="0.3 0 0" rpy="0 0 0"/></joint>
</robot>"""


def test_a_transmission_joint_is_neither_read_nor_written():
    root = urdf_text.parse(TRANSMISSION_FIRST, "robot.urdf")
    assert np.array_equal(urdf_text.joint_origin(root, "j1", "robot.urdf")[:3, 3], [0.0, 0.0, 0.5])
    T = np.eye(4)
    T[:3, 3] = [0.01, 0.0, 0.5]
    urdf_text.set_joint_origin(root, "j1", T, "robot.urdf")
    transmission_joint = root.find("transmission/joint")
    assert transmission_joint is not None and transmission_joint.find("origin") is None
    assert np.array_equal(urdf_text.joint_origin(root, "j1", "robot.urdf")[:3, 3], [0.01, 0.0, 0.5])


def test_a_joint_name_used_twice_in_the_tree_is_refused():
    text = TRANSMISSION_FIRST.replace('<joint name="tool_joint"', '<joint name="j1"')
    root = urdf_text.parse(text, "robot.urdf")
    with pytest.raises(InputError, match=r"^robot\.urdf: 2 joints are named 'j1'$"):
        urdf_text.joint_origin(root, "j1", "robot.urdf")
