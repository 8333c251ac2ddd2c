"""SuperBot modules, trees and their legkit models: geometry checked against first principles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from legkit.robots import superbot as sb


def test_mated_connectors_face_each_other_and_the_relation_is_symmetric():
    for angle in sb.ANGLES_DEG:
        mate = sb.mate_rotation(angle)
        assert np.allclose(mate @ mate, np.eye(3), atol=0)  # genderless: the same seen from both sides
        assert np.allclose(mate @ [0, 0, 1], [0, 0, -1], atol=0)  # normals opposite
        assert np.isclose(np.linalg.det(mate), 1.0)
        # The partner's x axis is turned by `angle` about the face normal.
        assert np.allclose(mate @ [1, 0, 0], [np.cos(np.radians(angle)), np.sin(np.radians(angle)), 0], atol=1e-15)
    with pytest.raises(ValueError, match="angle_deg"):
        sb.mate_rotation(45)


@pytest.mark.parametrize(
    "connections, message",
    [
        ([(0, 3, 1, 0, 0), (0, 3, 2, 0, 0)], "already used"),
        ([(0, 3, 1, 0, 0), (1, 3, 0, 4, 0)], "not a tree"),
        ([(0, 0, 1, 0, 0), (0, 3, 2, 0, 0)], "A_end"),
        ([(0, 3, 1, 0, 45), (0, 4, 2, 0, 0)], "angle_deg"),
        ([(0, 3, 1, 7, 0), (0, 4, 2, 0, 0)], "connector 7"),
        ([(0, 3, 5, 0, 0), (0, 4, 2, 0, 0)], "module 5"),
        ([(0, 3, 1, 0, 0)], "has 2 connections"),
        ([(0, 3, 0, 4, 0), (0, 5, 1, 0, 0)], "itself"),
    ],
)
def test_invalid_trees_are_rejected_with_a_clear_error(connections, message):
    with pytest.raises(ValueError, match=message):
        sb.ModuleTree(3, connections)


def test_bad_argument_types_and_values():
    with pytest.raises(TypeError, match="n_modules"):
        sb.ModuleTree(2.0, [])
    with pytest.raises(ValueError, match="width"):
        sb.ModuleParameters(width=-1.0)
    with pytest.raises(ValueError, match="branches"):
        sb.random_tree(20, 6, 0)
    with pytest.raises(TypeError, match="seed"):
        sb.random_tree(20, 4, 0.5)


@examples(40)
@given(st.integers(1, 12), st.integers(1, 5), st.integers(0, 10_000), st.integers(0, 10_000))
def test_model_places_mated_connectors_face_to_face(n_modules, branches, seed, angle_seed):
    branches = min(branches, n_modules)
    tree = sb.random_tree(n_modules, branches, seed)
    model, layout = tree.to_model()
    q = np.random.default_rng(angle_seed).uniform(-np.pi, np.pi, model.nq)
    rotation, translation = layout.module_poses(model, q)
    part_rotation, part_translation = sb.module_kinematics(layout.module_angles(q), tree.parameters)
    connector_rotation, connector_position = tree.parameters.connector_frames()

    def connector_world(module, connector):
        part = 3 if sb.CONNECTOR_BLOCK[connector] else 0
        r = rotation[module] @ part_rotation[module, part]
        t = translation[module] + rotation[module] @ part_translation[module, part]
        return r @ connector_rotation[connector], t + r @ connector_position[connector]

    for c in tree.connections:
        r_a, p_a = connector_world(c.module_a, c.connector_a)
        r_b, p_b = connector_world(c.module_b, c.connector_b)
        assert np.allclose(p_a, p_b, atol=1e-12)
        assert np.allclose(r_a.T @ r_b, sb.mate_rotation(c.angle_deg), atol=1e-12)
    # The root stands vertically at the origin, and the model's bodies are where the module kinematics say.
    assert np.allclose(rotation[0], np.eye(3)) and np.allclose(translation[0], 0)
    poses = lk.forward_kinematics(model, q)
    for n in range(tree.n_modules):
        for part in range(4):
            body_rotation = poses[layout.part_bodies[n, part], :3, :3]
            assert np.allclose(body_rotation, rotation[n] @ part_rotation[n, part], atol=1e-12)
    assert np.isclose(model.total_mass, tree.n_modules * tree.parameters.mass)


def test_module_kinematics_rotates_each_joint_about_its_axis():
    parameters = sb.ModuleParameters()
    w = parameters.width
    rotation, translation = sb.module_kinematics(np.array([np.pi / 2, 0.0, 0.0]), parameters)
    # Pitch 1 by 90 degrees about x at z = 0.75 w: block B's centre (0, 0, 1.625 w) goes to (0, -0.875 w, 0.75 w).
    centre = rotation[3] @ [0, 0, 1.625 * w] + translation[3]
    assert np.allclose(centre, [0, -0.875 * w, 0.75 * w], atol=1e-15)
    rotation, translation = sb.module_kinematics(np.array([0.0, 0.3, 0.0]), parameters)
    # The roll joint turns B about the long axis: points on the axis stay, points off it turn by 0.3 about z.
    assert np.allclose(rotation[3] @ [0, 0, 2 * w] + translation[3], [0, 0, 2 * w], atol=1e-15)
    turned = [0.5 * w * np.cos(0.3), 0.5 * w * np.sin(0.3), 2 * w]
    assert np.allclose(rotation[3] @ [0.5 * w, 0, 2 * w] + translation[3], turned, atol=1e-15)
    rotation, translation = sb.module_kinematics(np.array([0.0, 0.0, np.pi / 2]), parameters)
    # Pitch 2 by 90 degrees about x at z = 1.25 w: B's centre goes to (0, -0.375 w, 1.25 w); the other parts stay.
    assert np.allclose(rotation[3] @ [0, 0, 1.625 * w] + translation[3], [0, -0.375 * w, 1.25 * w], atol=1e-15)
    assert np.allclose(rotation[:3], np.eye(3), atol=0) and np.allclose(translation[:3], 0.0, atol=0)


def test_random_tree_matches_the_seed_experiment():
    tree = sb.random_tree(20, 4, seed=3)
    model, layout = tree.to_model()
    assert tree.n_modules == 21 and model.nv == 63
    assert np.isclose(model.total_mass, 21 * 0.05)
    # Four branches of five modules, each hanging off its own root connector.
    links = tree.neighbours()
    root_links = links[0]
    assert len(root_links) == 4
    for _, first, _, _ in root_links:
        seen, stack = {0, first}, [first]
        while stack:
            for _, v, _, _ in links[stack.pop()]:
                if v not in seen:
                    seen.add(v)
                    stack.append(v)
        assert len(seen) - 1 == 5
    cells = tree.lattice_cells()
    assert len({tuple(c) for c in cells}) == 2 * tree.n_modules  # no two blocks overlap
    assert cells[:, 2].min() >= 0  # nothing below the ground
    again = sb.random_tree(20, 4, seed=3)
    assert again.connections == tree.connections
    assert sb.random_tree(20, 4, seed=4).connections != tree.connections


def test_diameter_of_a_chain():
    chain = sb.ModuleTree(4, [(0, 3, 1, 0, 0), (1, 3, 2, 0, 90), (2, 3, 3, 0, 180)])
    assert chain.diameter() == 3
    assert sb.ModuleTree(1, []).diameter() == 0
