"""A URDF's coordinates and joint names come in Pinocchio's order, on random trees.

`pin.buildModelFromUrdf` walks the tree depth first from the root link, a link's children in the order of their
joints' names (urdfdom keeps the joints in a `std::map` by name), whatever their order in the file; a fixed
joint is walked through. Random trees, their links and joints written in a shuffled order under names whose byte
order differs from their file order (upper case before lower, "j10" before "j2", a joint named as a link), load
in legkit with Pinocchio's joint names in q order and Pinocchio's RNEA and ABA with no permutation (a continuous
joint's angle given to Pinocchio as its cosine and sine).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from test_urdf_robots import Twin, assert_close

JOINT_TYPES = ["revolute", "continuous", "prismatic", "fixed"]
NAMES = st.text(alphabet="aAbB_19", min_size=1, max_size=3)


@st.composite
def trees(draw: st.DrawFn) -> tuple[str, list[tuple[str, int, int, str]]]:
    """(URDF text, joints as (name, parent link, child link, type)): link 0 the root, each other link's parent an
    earlier link; links and joints written in a shuffled order."""
    n = draw(st.integers(2, 9))
    links = draw(st.lists(NAMES.map(lambda s: f"L{s}"), min_size=n, max_size=n, unique=True))
    names = draw(st.lists(st.one_of(NAMES, st.sampled_from(links)), min_size=n - 1, max_size=n - 1, unique=True))
    joints = [(names[k - 1], draw(st.integers(0, k - 1)), k, draw(st.sampled_from(JOINT_TYPES))) for k in range(1, n)]
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    elements = []
    for link in links:
        inertia = rng.uniform(0.05, 0.1, 3)  # principal moments that satisfy the triangle inequality
        elements.append(
            f'<link name="{link}"><inertial><origin xyz="{" ".join(map(str, rng.normal(0, 0.1, 3)))}"/>'
            f'<mass value="{rng.uniform(0.5, 2.0)}"/><inertia ixx="{inertia[0]}" iyy="{inertia[1]}" izz="{inertia[2]}" '
            'ixy="0" ixz="0" iyz="0"/></inertial></link>'
        )
    for name, parent, child, kind in joints:
        elements.append(
            f'<joint name="{name}" type="{kind}"><parent link="{links[parent]}"/><child link="{links[child]}"/>'
            f'<origin xyz="{" ".join(map(str, rng.normal(0, 0.3, 3)))}" rpy="{" ".join(map(str, rng.uniform(-1, 1, 3)))}"/>'
            f'<axis xyz="{" ".join(map(str, rng.normal(size=3)))}"/><limit lower="-1" upper="1" effort="10" velocity="10"/></joint>'
        )
    order = draw(st.permutations(range(len(elements))))
    return '<robot name="random">' + "".join(elements[k] for k in order) + "</robot>", joints


def depth_first_by_name(joints: list[tuple[str, int, int, str]]) -> list[str]:
    """The moving joints in the order the rule above says, walked here by recursion."""
    children: dict[int, list[tuple[str, int, int, str]]] = {}
    for joint in joints:
        children.setdefault(joint[1], []).append(joint)
    order: list[str] = []

    def walk(link: int) -> None:
        for name, _, child, kind in sorted(children.get(link, []), key=lambda j: j[0].encode()):
            if kind != "fixed":
                order.append(name)
            walk(child)

    walk(0)
    return order


@examples(60)
@given(trees(), st.booleans(), st.integers(0, 2**32 - 1))
def test_random_trees_load_in_pinocchios_order_with_its_joint_names_and_dynamics(tree, floating, seed):
    xml, joints = tree
    model = lk.Model.from_urdf(xml, floating_base=floating)
    reference = pin.buildModelFromXML(xml, pin.JointModelFreeFlyer()) if floating else pin.buildModelFromXML(xml)
    assert model.joint_names == ["root_joint"] * floating + depth_first_by_name(joints)
    twin = Twin(model, reference)  # checks the names, and that q and v are laid out alike
    data = reference.createData()
    rng = np.random.default_rng(seed)
    q, q_pin = twin.state(rng)
    v, a, tau = (rng.normal(size=model.nv) for _ in range(3))
    assert_close(lk.rnea(model, q, v, a), pin.rnea(reference, data, q_pin, v, a), "rnea")
    assert_close(lk.aba(model, q, v, tau), pin.aba(reference, data, q_pin, v, tau), "aba")


def test_a_joints_coordinates_are_found_by_its_name_and_an_unknown_name_is_an_index_error():
    xml = """<robot name="r"><link name="trunk"/><link name="thigh"/><link name="shin"/><link name="toe"/>
        <joint name="knee" type="revolute"><parent link="thigh"/><child link="shin"/><limit lower="-1" upper="1"/></joint>
        <joint name="toe_mount" type="fixed"><parent link="shin"/><child link="toe"/></joint>
        <joint name="hip" type="prismatic"><parent link="trunk"/><child link="thigh"/><limit lower="-1" upper="1"/></joint>
        </robot>"""
    model = lk.Model.from_urdf(xml, floating_base=True)
    assert model.joint_names == ["root_joint", "hip", "knee"]
    assert model.names == ["trunk", "thigh", "shin", "toe"]
    assert [model.joint_index(name) for name in ["root_joint", "hip", "knee", "toe_mount"]] == [0, 1, 2, 3]
    knee = model.joint_index("knee")
    assert (model.idx_q[knee], model.idx_v[knee], model.joint_type(knee)) == (8, 7, "revolute")
    with pytest.raises(IndexError, match='name: no joint is named "shin"'):
        model.joint_index("shin")  # a link's name, not a joint's


def test_built_models_name_each_joint_after_its_body():
    model = lk.Model(floating_base=True)
    arm = model.add_revolute(0, [0, 0, 1], name="arm")
    model.add_fixed(arm, name="tool")
    assert model.joint_names == ["root_joint", "arm"]
    assert model.joint_index("tool") == 2
    assert lk.Model().joint_names == []
