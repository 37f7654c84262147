"""Bad robot files (issue 21, item 4): every case gets one line naming the file, the element and its
line; skipped elements and missing meshes are one warning each.  The cases are the list of bad files
tried (the ids name them)."""

from __future__ import annotations

import re
import warnings

import pytest

from kronlag.core.errors import ModelFileError
from kronlag.model.robot_formats import load_robot

URDF_OK = '''<robot name="r">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0.5 0 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint>
  <link name="b"><inertial><origin xyz="0.5 0 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="1 0 0"/><axis xyz="0 0 1"/></joint>
</robot>'''
B_INERTIAL = '<inertial><origin xyz="0.5 0 0"/><mass value="1"/>\n    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>\n  <joint name="j2"'
MJCF_OK = '''<mujoco model="m"><compiler angle="radian"/><worldbody>
  <body name="arm"><joint name="hinge" axis="0 1 0"/>
    <inertial pos="0.5 0 0" mass="1" diaginertia="0.001 0.02 0.02"/>
    <body name="tip" pos="1 0 0"><joint name="hinge2" axis="0 1 0"/>
      <inertial pos="0.5 0 0" mass="1" diaginertia="0.001 0.02 0.02"/></body></body>
</worldbody><equality></equality></mujoco>'''
SDF_OK = '''<sdf version="1.7"><model name="m">
  <link name="arm"><inertial><pose>0.5 0 0 0 0 0</pose><mass>1</mass><inertia><ixx>0.001</ixx>
    <iyy>0.02</iyy><izz>0.02</izz></inertia></inertial></link>
  <joint name="hinge" type="revolute"><parent>world</parent><child>arm</child><axis><xyz>0 1 0</xyz></axis></joint>
  <link name="tip"><pose>1 0 0 0 0 0</pose><inertial><pose>0.5 0 0 0 0 0</pose><mass>1</mass><inertia><ixx>0.001</ixx>
    <iyy>0.02</iyy><izz>0.02</izz></inertia></inertial></link>
  <joint name="hinge2" type="revolute"><parent>arm</parent><child>tip</child><axis><xyz>0 1 0</xyz></axis></joint>
</model></sdf>'''
LAUGHS = '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>\n'

#: (file name, text, a regular expression the one line must match)
CASES = [
    ("malformed.urdf", URDF_OK.replace('<link name="base"/>', '<link name="base">'), r"malformed.urdf:\d+: malformed XML at column \d+: mismatched tag"),
    ("unknown_type.urdf", URDF_OK.replace('name="j2" type="revolute"', 'name="j2" type="hinge"'), r":8: <joint name='j2'>: unknown joint type 'hinge'"),
    ("no_mass.urdf", URDF_OK.replace('<mass value="1"/>\n    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>\n  <joint name="j2"', '\n    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>\n  <joint name="j2"'), r":6: <link name='b'>: <inertial> has no <mass"),
    ("negative_mass.urdf", URDF_OK.replace(B_INERTIAL, B_INERTIAL.replace('value="1"', 'value="-1"')), r":6: <link name='b'>: <inertial>: mass = -1 .*must not be negative"),
    ("not_definite.urdf", URDF_OK.replace(B_INERTIAL, B_INERTIAL.replace('ixx="0.01"', 'ixx="-0.01"')), r":6: <link name='b'>: <inertial>: the inertia tensor is not positive semidefinite"),
    ("triangle.urdf", URDF_OK.replace(B_INERTIAL, B_INERTIAL.replace('izz="0.02"', 'izz="0.05"')), r":6: <link name='b'>: <inertial>: .*triangle inequality"),
    ("zero_mass_leaf.urdf", URDF_OK.replace(B_INERTIAL, "</link>\n  <joint name=\"j2\"").replace('<link name="b">', '<link name="b">'), r":6: <link name='b'>: is a zero-mass leaf"),
    ("mimic_unknown.urdf", URDF_OK.replace('<axis xyz="0 0 1"/></joint>\n</robot>', '<axis xyz="0 0 1"/><mimic joint="nope"/></joint>\n</robot>'), r":8: <mimic>: of joint 'j2': 'nope' is not a joint of the file"),
    ("two_roots.urdf", URDF_OK.replace('<link name="base"/>', '<link name="base"/><link name="other"/>'), r":2: <link name='other'>: a second root link"),
    ("two_parents.urdf", URDF_OK.replace('<parent link="a"/><child link="b"/>', '<parent link="base"/><child link="a"/>'), r":8: <joint name='j2'>: link 'a' already has the parent joint 'j1'"),
    ("robot.urdf.xacro", URDF_OK, r"robot.urdf.xacro: this is a xacro file, which kronlag does not evaluate; run `xacro"),
    ("xacro_inside.urdf", URDF_OK.replace('<robot name="r">', '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:property name="l" value="1"/>'), r":1: <xacro:property>: this is a xacro file.*run `xacro"),
    ("laughs.urdf", LAUGHS + URDF_OK.replace('name="r"', 'name="&b;"'), r"laughs.urdf:\d+: refused: the file declares the entity 'a'"),
    ("external.urdf", '<!DOCTYPE r [<!ENTITY s SYSTEM "file:///etc/passwd">]>\n' + URDF_OK.replace('name="r"', 'name="&s;"'), r"external.urdf:\d+: refused: the file declares"),
    ("malformed.xml", MJCF_OK.replace("</worldbody>", "</world>"), r"malformed.xml:\d+: malformed XML at column \d+: mismatched tag"),
    ("unknown_type.xml", MJCF_OK.replace('name="hinge2" axis', 'name="hinge2" type="spiral" axis'), r":4: <joint name='hinge2'>: unknown joint type 'spiral'; MJCF joint types are hinge, slide, ball, free"),
    ("no_inertia.xml", MJCF_OK.replace(' diaginertia="0.001 0.02 0.02"/></body></body>', '/></body></body>'), r":5: <inertial>: needs the attribute diaginertia"),
    ("negative_mass.xml", MJCF_OK.replace('mass="1" diaginertia="0.001 0.02 0.02"/></body>', 'mass="-1" diaginertia="0.001 0.02 0.02"/></body>'), r":4: <body name='tip'>: <inertial>: mass = -1 .*must not be negative"),
    ("triangle.xml", MJCF_OK.replace('diaginertia="0.001 0.02 0.02"/></body></body>', 'diaginertia="0.001 0.02 0.05"/></body></body>'), r":4: <body name='tip'>: <inertial>: .*triangle inequality"),
    ("zero_mass_leaf.xml", MJCF_OK.replace('\n      <inertial pos="0.5 0 0" mass="1" diaginertia="0.001 0.02 0.02"/></body>', '</body>'), r":4: <body name='tip'>: is a zero-mass leaf"),
    ("connect_unknown.xml", MJCF_OK.replace("<equality>", '<equality><connect body1="tip" body2="nope" anchor="1 0 0"/>'), r":6: <connect>: body2='nope' is not a body of the file"),
    ("joint_unknown.xml", MJCF_OK.replace("<equality>", '<equality><joint joint1="hinge" joint2="nope"/>'), r":6: <joint>: names the joint 'nope', which is not a hinge or slide"),
    ("unclosable.xml", MJCF_OK.replace("<equality>", '<equality><weld name="w" body1="world" body2="tip" relpose="0 0 0 0.7071068 0.7071068 0 0"/>'), r":6: <weld name='w'>: the loop cannot be closed near the reference pose: constraint residual"),
    ("laughs.xml", LAUGHS + MJCF_OK.replace('model="m"', 'model="&b;"'), r"laughs.xml:\d+: refused: the file declares the entity 'a'"),
    ("malformed.sdf", SDF_OK.replace("</model>", "</mode>"), r"malformed.sdf:\d+: malformed XML at column \d+: mismatched tag"),
    ("unknown_type.sdf", SDF_OK.replace('name="hinge2" type="revolute"', 'name="hinge2" type="spiral"'), r":7: <joint name='hinge2'>: type 'spiral'"),
    ("no_inertia.sdf", SDF_OK.replace('<mass>1</mass><inertia><ixx>0.001</ixx>\n    <iyy>0.02</iyy><izz>0.02</izz></inertia></inertial></link>\n  <joint name="hinge2"', '<mass>1</mass></inertial></link>\n  <joint name="hinge2"'), r":5: <link name='tip'>: <inertial> has no <inertia>"),
    ("negative_mass.sdf", SDF_OK.replace("<mass>1</mass>", "<mass>-1</mass>", 1), r":2: <link name='arm'>: <inertial>: mass = -1 .*must not be negative"),
    ("zero_mass_leaf.sdf", SDF_OK.replace('<inertial><pose>0.5 0 0 0 0 0</pose><mass>1</mass><inertia><ixx>0.001</ixx>\n    <iyy>0.02</iyy><izz>0.02</izz></inertia></inertial></link>\n  <joint name="hinge2"', '</link>\n  <joint name="hinge2"'), r":5: <link name='tip'>: is a zero-mass leaf"),
    ("loop_unknown.sdf", SDF_OK.replace("</model>", '<joint name="loop" type="ball"><parent>nope</parent><child>tip</child></joint></model>'), r":8: <joint name='loop'>: <parent>nope</parent> is not a link of the model"),
    ("two_roots.sdf", SDF_OK.replace("</model>", '<link name="stray"><inertial><mass>1</mass><inertia><ixx>1</ixx><iyy>1</iyy><izz>1</izz></inertia></inertial></link></model>'), r"<link name='stray'>"),
    ("unclosable.sdf", SDF_OK.replace("</model>", '<joint name="loop" type="universal"><parent>world</parent><child>tip</child><axis><xyz>0 1 0</xyz></axis><axis2><xyz>0 1 0</xyz></axis2></joint></model>'), r":8: <joint name='loop'>: row cross: the constraint cannot be closed at the reference pose: residual 1"),
    ("laughs.sdf", LAUGHS + SDF_OK.replace('name="m"', 'name="&b;"'), r"laughs.sdf:\d+: refused: the file declares the entity 'a'"),
]
WARNINGS = [
    ("skipped.urdf", URDF_OK.replace("</robot>", "<transmission/><gazebo/><gazebo/></robot>"), r"skipped.urdf: not used by kronlag \(skipped\): robot/gazebo \(2\), robot/transmission"),
    ("missing_mesh.urdf", URDF_OK.replace('<link name="base"/>', '<link name="base"><visual><geometry><mesh filename="package://gone/m.stl"/></geometry></visual></link>'), r"missing_mesh.urdf: meshes drawn as placeholders: package://gone/m.stl \(not found\)"),
    ("skipped.xml", MJCF_OK.replace("</mujoco>", "<actuator/><sensor/></mujoco>"), r"skipped.xml: not used by kronlag \(skipped\): mujoco/actuator, mujoco/sensor"),
    ("skipped.sdf", SDF_OK.replace("</model>", "<plugin/><plugin/></model>"), r"skipped.sdf: not used by kronlag \(skipped\): .*plugin \(2\)"),
]


@pytest.mark.parametrize("name, text, expected", CASES, ids=[case[0] for case in CASES])
def test_bad_file_is_one_located_line(tmp_path, name, text, expected):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ModelFileError) as caught, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_robot(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(str(path)), message
    assert re.search(expected, message), message


@pytest.mark.parametrize("name, text, expected", WARNINGS, ids=[case[0] for case in WARNINGS])
def test_skipped_and_missing_are_one_warning(tmp_path, name, text, expected):
    path = tmp_path / name
    path.write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_robot(path)
    messages = [str(warning.message) for warning in caught]
    assert len(messages) == 1 and re.search(expected, messages[0]), messages
