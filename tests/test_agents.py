"""Distributed mass-property agents: exact after `diameter` rounds, silent afterwards, robust to an unreliable bus.

The reference is brute force: for every module and connector, the set of modules beyond that connector is
found by a graph search, and their bodies are summed with lk.MassProperties from forward kinematics.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from legkit.agents import AgentNetwork, BusConfig, Channel, GroundContact, moments
from legkit.agents import bus as bus_module
from legkit.robots import superbot as sb

TOLERANCE = 1e-9


def ground_root(line_point=(0.0, 0.0, 0.0), line_direction=(0.0, 0.0, 1.0)):
    return [GroundContact(0, 0, np.eye(3), np.zeros(3), np.array(line_point), np.array(line_direction))]


def brute_force(tree, model, layout, q):
    """Per module: {connector: MassProperties beyond it} and the total, all in the module's frame."""
    poses = lk.forward_kinematics(model, q)
    rotation, translation = layout.module_poses(model, q)
    world = [
        sum((model.body(b).transformed(poses[b]) for b in layout.part_bodies[n]), lk.MassProperties.zero())
        for n in range(tree.n_modules)
    ]
    links = tree.neighbours()
    beyond, totals = [], []
    total_world = sum(world, lk.MassProperties.zero())
    for n in range(tree.n_modules):
        inverse = (rotation[n].T, -rotation[n].T @ translation[n])
        per_connector = {}
        for own, v, _, _ in links[n]:
            seen, stack = {n, v}, [v]
            while stack:
                for _, x, _, _ in links[stack.pop()]:
                    if x not in seen:
                        seen.add(x)
                        stack.append(x)
            part = sum((world[m] for m in seen - {n}), lk.MassProperties.zero())
            per_connector[own] = part.transformed(*inverse)
        beyond.append(per_connector)
        totals.append(total_world.transformed(*inverse))
    return beyond, totals


def assert_matches(network, reference, tolerance=TOLERANCE):
    beyond, totals = reference
    mass, com, inertia = moments.unpack(network.connector_estimates())
    total_mass, total_com, total_inertia = moments.unpack(network.total_estimates())
    for n, per_connector in enumerate(beyond):
        for slot, truth in per_connector.items():
            assert abs(mass[n, slot] - truth.mass) < tolerance
            assert np.max(np.abs(com[n, slot] - truth.com)) < tolerance
            assert np.max(np.abs(inertia[n, slot] - truth.inertia)) < tolerance
        assert abs(total_mass[n] - totals[n].mass) < tolerance
        assert np.max(np.abs(total_com[n] - totals[n].com)) < tolerance
        assert np.max(np.abs(total_inertia[n] - totals[n].inertia)) < tolerance


def largest_error(network, reference):
    beyond, _ = reference
    mass = moments.unpack(network.connector_estimates())[0]
    return max(abs(mass[n, s] - t.mass) for n, pc in enumerate(beyond) for s, t in pc.items())


trees = st.builds(
    lambda n, b, seed: sb.random_tree(n, min(b, n), seed), st.integers(1, 14), st.integers(1, 5), st.integers(0, 10_000)
)


@pytest.mark.slow
@examples(60)
@given(trees, st.integers(0, 10_000))
def test_exact_after_diameter_rounds_then_silent(tree, angle_seed):
    model, layout = tree.to_model()
    q = np.random.default_rng(angle_seed).uniform(-np.pi, np.pi, model.nq)
    network = AgentNetwork(tree, ground=ground_root(), angles=layout.module_angles(q))
    reference = brute_force(tree, model, layout, q)
    diameter = tree.diameter()
    network.run(diameter - 1)
    # Exactly `diameter`: one round earlier, some estimate still misses at least one module's mass.
    assert largest_error(network, reference) > 0.5 * tree.parameters.mass
    network.run(1)
    assert_matches(network, reference)
    assert network.estimate_errors(model, layout, q).largest < TOLERANCE  # against lk.subtree_mass_properties
    assert network.quiescent
    assert network.run(5) == 0  # no message after quiescence
    # Every agent knows its world pose and which side of it holds the ground.
    rotation, translation = layout.module_poses(model, q)
    believed_rotation, believed_translation = network.world_poses()
    assert np.allclose(believed_rotation, rotation, atol=1e-12)
    assert np.allclose(believed_translation, translation, atol=1e-12)
    assert np.all(network.leader == 0)


def test_single_module_network():
    tree = sb.ModuleTree(1, [])
    model, layout = tree.to_model()
    network = AgentNetwork(tree, ground=ground_root(), angles=np.array([[0.3, -0.2, 0.1]]))
    assert network.quiescent and network.transmissions == 0
    q = np.array([0.3, -0.2, 0.1])
    assert network.estimate_errors(model, layout, q).largest < TOLERANCE


@examples(25)
@given(trees, st.integers(0, 10_000), st.integers(0, 10_000))
def test_estimates_track_moving_joints(tree, angle_seed, move_seed):
    model, layout = tree.to_model()
    rng = np.random.default_rng(angle_seed)
    q = rng.uniform(-np.pi, np.pi, model.nq)
    network = AgentNetwork(tree, ground=ground_root(), angles=layout.module_angles(q))
    network.run(tree.diameter())
    moved = np.random.default_rng(move_seed).random(model.nq) < 0.3
    q = np.where(moved, rng.uniform(-np.pi, np.pi, model.nq), q)
    network.observe(layout.module_angles(q))
    network.run_until_quiescent()
    assert_matches(network, brute_force(tree, model, layout, q))


@pytest.mark.slow
@pytest.mark.parametrize("loss, duplication, delay_max", [(0.3, 0.2, 4), (0.0, 0.3, 7), (0.6, 0.0, 1)])
@examples(15)
@given(tree=trees, angle_seed=st.integers(0, 10_000), bus_seed=st.integers(0, 10_000))
def test_unreliable_bus_is_eventually_exact(loss, duplication, delay_max, tree, angle_seed, bus_seed):
    model, layout = tree.to_model()
    q = np.random.default_rng(angle_seed).uniform(-np.pi, np.pi, model.nq)
    bus = BusConfig(mode="async", delay_min=1, delay_max=delay_max, loss=loss, duplication=duplication, retransmit_after=3, seed=bus_seed)
    network = AgentNetwork(tree, bus=bus, ground=ground_root(), angles=layout.module_angles(q))
    network.run(50)
    network.reconfigure(dataclasses.replace(bus, loss=0.0))  # loss stops; delays and reordering go on
    network.run_until_quiescent(max_rounds=10_000)
    assert_matches(network, brute_force(tree, model, layout, q))
    assert np.all(network.leader == 0)
    rotation, _ = layout.module_poses(model, q)
    assert np.allclose(network.world_poses()[0], rotation, atol=1e-12)
    assert network.run(5) == 0


def test_same_seed_same_run_and_reordering_happens():
    tree = sb.random_tree(12, 3, 1)
    runs = []
    for _ in range(2):
        bus = BusConfig(mode="async", delay_min=1, delay_max=6, loss=0.2, duplication=0.2, seed=7)
        network = AgentNetwork(tree, bus=bus, ground=ground_root())
        network.run(40)
        runs.append((network.transmissions, network.acknowledgements, network.estimates_connector_frame.copy()))
    assert runs[0][0] == runs[1][0] and runs[0][1] == runs[1][1]
    assert np.array_equal(runs[0][2], runs[1][2])
    assert network.mass_channel.lost > 0 and network.mass_channel.duplicated > 0 and network.mass_channel.retransmissions > 0


def test_randomised_leader_election_among_ground_modules():
    tree = sb.random_tree(12, 3, 2)
    grounded = [0, 4, 9]
    leaders = set()
    for seed in range(12):
        ground = [GroundContact(m, 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0])) for m in grounded]
        network = AgentNetwork(tree, bus=BusConfig(seed=seed), ground=ground)
        network.run_until_quiescent()
        assert len(set(network.leader)) == 1  # everybody agrees
        leaders.add(int(network.leader[0]))
        # The uplink of every non-leader points one step closer to the leader.
        leader = int(network.leader[0])
        assert network.uplink[leader] == -1
        partner = network.partner
        for n in range(tree.n_modules):
            if n != leader:
                assert partner[n, network.uplink[n]] >= 0
    assert leaders <= set(grounded) and len(leaders) > 1


@examples(60)
@given(
    st.floats(0.01, 10), st.tuples(*[st.floats(-2, 2)] * 3), st.tuples(*[st.floats(0.01, 1)] * 3),
    st.tuples(*[st.floats(-1, 1)] * 4).filter(lambda v: np.linalg.norm(v) > 0.1), st.tuples(*[st.floats(-3, 3)] * 3),
)
def test_moment_algebra_matches_mass_properties(mass, centre, size, quaternion, translation):
    x, y, z, w = np.array(quaternion) / np.linalg.norm(quaternion)
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    body = lk.MassProperties.solid_box(mass, size, center=centre, rotation=rotation)
    packed = moments.pack(body.mass, body.com, body.inertia)
    moved = body.transformed(rotation, translation)
    m, c, inertia = moments.unpack(moments.transform(rotation, np.array(translation), packed))
    assert np.isclose(m, moved.mass) and np.allclose(c, moved.com, atol=1e-12)
    assert np.allclose(inertia, moved.inertia, atol=1e-12 * max(1.0, np.abs(moved.inertia).max()))
    other = lk.MassProperties.point(2.0, [0.5, -0.3, 1.0])
    m, c, inertia = moments.unpack(packed + moments.pack(other.mass, other.com, other.inertia))
    both = body + other
    assert np.isclose(m, both.mass) and np.allclose(c, both.com) and np.allclose(inertia, both.inertia, atol=1e-12)


def test_bad_input_is_rejected_and_leaves_state_unchanged():
    tree = sb.random_tree(6, 2, 0)
    network = AgentNetwork(tree, ground=ground_root())
    angles = network.angles.copy()
    with pytest.raises(ValueError, match="angles"):
        network.observe(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="angles"):
        network.observe(np.full((tree.n_modules, 3), np.nan))
    assert np.array_equal(network.angles, angles)
    with pytest.raises(ValueError, match="mode"):
        BusConfig(mode="radio")
    with pytest.raises(ValueError, match="loss"):
        BusConfig(mode="async", loss=1.5)
    with pytest.raises(ValueError, match="mode"):
        BusConfig(mode="sync", loss=0.1)
    with pytest.raises(ValueError, match="mode"):
        network.reconfigure(BusConfig(mode="async"))
    with pytest.raises(TypeError, match="trees"):
        AgentNetwork([])
    with pytest.raises(ValueError, match="ground"):
        AgentNetwork(tree, ground=[GroundContact(99, 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0, 0, 1.0]))])


def test_component_major_forms_match_the_array_forms():
    # The agents keep their state component-major; those kernels must agree with the (..., 13) / (..., 3, 3) forms.
    rng = np.random.default_rng(5)
    rotation = np.linalg.qr(rng.standard_normal((7, 4, 3, 3)))[0]
    translation = rng.standard_normal((7, 4, 3))
    packed = moments.pack(rng.uniform(0.1, 1.0, 4), rng.standard_normal((4, 3)), np.eye(3) * rng.uniform(0.1, 1.0, (4, 1, 1)))
    expected = moments.transform(rotation, translation, packed)
    got = moments.transform_components(np.moveaxis(rotation, (2, 3), (0, 1)), np.moveaxis(translation, 2, 0), packed.T[:, None])
    assert np.array_equal(np.moveaxis(got, 0, -1), expected)
    vector = rng.standard_normal((7, 4, 3))
    assert np.allclose(np.moveaxis(moments.rotate_components(np.moveaxis(rotation, (2, 3), (0, 1)), np.moveaxis(vector, 2, 0)), 0, -1),
                       np.einsum("...ij,...j->...i", rotation, vector), atol=1e-15)
    inverse_rotation, inverse_translation = moments.inverse_pose(rotation, translation)
    assert np.allclose(np.einsum("...ij,...j->...i", inverse_rotation, translation) + inverse_translation, 0.0, atol=1e-15)
    angles = rng.uniform(-np.pi, np.pi, (5, 3))
    parts_rotation, parts_translation = sb.module_kinematics(angles, sb.ModuleParameters())
    rotation_components, translation_components = sb.module_kinematics_components(angles, sb.ModuleParameters())
    assert np.array_equal(np.moveaxis(rotation_components, (0, 1, 2), (-2, -1, -3)), parts_rotation)
    assert np.array_equal(np.moveaxis(translation_components, (0, 1), (-1, -2)), parts_translation)


def test_network_queries_agree_with_each_other():
    tree = sb.random_tree(10, 3, 4)
    model, layout = tree.to_model()
    rng = np.random.default_rng(4)
    q = rng.uniform(-1, 1, model.nq)
    network = AgentNetwork(tree, ground=ground_root(), angles=layout.module_angles(q))
    network.run_until_quiescent()
    network.observe(layout.module_angles(q + 0.1 * rng.standard_normal(model.nq)))
    network.run(1)
    # Algorithm 2's module-frame copies are the connector-frame estimates turned by the current connector frames.
    assert np.array_equal(network.current_connector_estimates(), network.connector_estimates())
    per_block = network.current_connector_estimates().reshape(tree.n_modules, 2, 3, moments.WIDTH)
    assert np.array_equal(network.block_estimates(), per_block[:, :, 0] + per_block[:, :, 1] + per_block[:, :, 2] + 0.0)
    assert np.array_equal(network.estimates_connector_frame[~network.connected], np.zeros((np.count_nonzero(~network.connected), moments.WIDTH)))
    # Connector frames: block A's fixed in the module frame, block B's carried by part 3.
    rotation_zero, position_zero = tree.parameters.connector_frames()
    assert np.allclose(network.connector_rotation[:, :3], rotation_zero[:3])
    assert np.allclose(network.connector_rotation[:, 3:], network.part_rotation[:, 3, None] @ rotation_zero[3:], atol=1e-15)
    expected = network.part_translation[:, 3, None] + np.einsum("nij,sj->nsi", network.part_rotation[:, 3], position_zero[3:])
    assert np.allclose(network.connector_position[:, 3:], expected, atol=1e-15)


def test_channel_delivers_in_connector_order_and_keeps_the_newest():
    tree = sb.random_tree(6, 2, 0)
    partner, partner_slot, _ = tree.connector_table()
    modules, slots = np.nonzero(partner >= 0)
    channel = Channel(partner, partner_slot, 2, BusConfig(), np.random.default_rng(0))
    channel.send_changed(0, modules, slots, np.stack([modules, slots], axis=1).astype(float))
    channel.send_changed(0, modules[:2], slots[:2], np.full((2, 2), 9.0))  # newer messages on two links
    receiver, receiver_slot, sender, sender_slot, payload = channel.deliver(1)
    assert np.array_equal(receiver * 6 + receiver_slot, np.sort(receiver * 6 + receiver_slot))
    assert np.array_equal(receiver, partner[sender, sender_slot]) and np.array_equal(receiver_slot, partner_slot[sender, sender_slot])
    newest = np.isin(sender * 6 + sender_slot, modules[:2] * 6 + slots[:2])
    assert np.all(payload[newest] == 9.0) and np.array_equal(payload[~newest], np.stack([sender, sender_slot], axis=1)[~newest])
    assert channel.in_flight == 0 and channel.transmissions == modules.size + 2


def grounded_roots(trees):
    """A ground contact at the root of every tree of a network of ``trees`` (numbered tree after tree)."""
    first = np.cumsum([0] + [t.n_modules for t in trees])[:-1]
    return [GroundContact(int(m), 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0])) for m in first]


@pytest.mark.slow
@examples(10)
@given(seeds=st.lists(st.integers(0, 10_000), min_size=2, max_size=3, unique=True), stream_seed=st.integers(0, 2**32))
def test_a_tree_on_its_own_stream_does_not_depend_on_the_other_trees(seeds, stream_seed):
    """With ``BusConfig.streams``, a tree's losses, duplicates, delays and delivery order are its own: the tree
    in a network beside other trees (before or after them) sends what it sends alone."""
    trees = [sb.random_tree(8, 2, s) for s in seeds]
    bus = BusConfig(mode="async", delay_max=5, loss=0.3, duplication=0.2, retransmit_after=3)
    own = stream_seed

    def run(order):
        network_trees = [trees[k] for k in order]
        streams = tuple((t.n_modules, own if k == 0 else 1000 + k) for k, t in zip(order, network_trees))
        network = AgentNetwork(network_trees, bus=dataclasses.replace(bus, streams=streams), ground=grounded_roots(network_trees))
        network.run(30)
        first = sum(t.n_modules for t in network_trees[:order.index(0)])
        mine = slice(first, first + trees[0].n_modules)
        return [c.sent_by_module[mine].copy() for c in network.channels], network.estimates_connector_frame[mine], network

    alone_sent, alone_estimates, alone = run([0])
    assert alone.mass_channel.lost > 0 and alone.mass_channel.duplicated > 0  # the bus does lose and duplicate
    for order in ([0, *range(1, len(trees))], [*range(1, len(trees)), 0]):
        sent, estimates, _ = run(order)
        assert all(np.array_equal(a, b) for a, b in zip(sent, alone_sent))
        assert np.array_equal(estimates, alone_estimates)
    # Another stream seed gives the tree other losses (the streams are seeded, not shared).
    bus = dataclasses.replace(bus, streams=((trees[0].n_modules, own + 1),))
    other = AgentNetwork(trees[0], bus=bus, ground=grounded_roots(trees[:1]))
    other.run(30)
    assert any(not np.array_equal(c.sent_by_module, a) for c, a in zip(other.channels, alone_sent))


@examples(20)
@given(calls=st.lists(st.tuples(st.integers(0, 2), st.integers(0, 3000), st.integers(1, 4)), min_size=1, max_size=12))
def test_stream_draws_are_each_generators_sequence_however_chunked(calls):
    """Each stream hands out its generator's uniforms in order, whatever the calls' sizes (beyond a chunk
    too) and the other streams' draws in the same calls."""
    slots = 6
    stream_of_module = np.array([0, 1, 1, 2])
    draws = bus_module._Draws(stream_of_module, [np.random.default_rng(s) for s in (5, 6, 7)], slots)
    got = {s: [] for s in range(3)}
    rng = np.random.default_rng(len(calls))
    for stream, count, width in calls:
        # ``count`` messages on links of ``stream`` mixed with as many on the other streams' links.
        mine = np.flatnonzero(np.repeat(stream_of_module, slots) == stream)
        links = np.concatenate([rng.choice(mine, count), rng.integers(0, slots * 4, count)])
        rng.shuffle(links)
        values = draws(links, width)
        assert values.shape == (links.size, width)
        for s in range(3):
            got[s].append(values[np.repeat(stream_of_module, slots)[links] == s].ravel())
    for s, seed in enumerate((5, 6, 7)):
        drawn = np.concatenate(got[s])
        assert np.array_equal(drawn, np.random.default_rng(seed).random(drawn.size))


def test_losses_and_duplicates_at_their_rates_and_delays_in_range():
    tree = sb.random_tree(14, 4, 3)
    partner, partner_slot, _ = tree.connector_table()
    modules, slots = np.nonzero(partner >= 0)
    bus = BusConfig(mode="async", delay_min=2, delay_max=5, loss=0.25, duplication=0.4, streams=((tree.n_modules, 9),))
    channel = Channel(partner, partner_slot, 1, bus, np.random.default_rng(0))
    delays = []
    for now in range(400):
        waiting = channel.in_flight
        channel.send_changed(now, modules, slots, np.full((modules.size, 1), float(now)))
        delays.append(channel._due[waiting:] - now)  # noqa: SLF001 - the messages this send put on the wire
        channel.deliver(now)
    sent = channel.transmissions + channel.acknowledgements
    assert abs(channel.lost / sent - 0.25) < 0.02
    assert abs(channel.duplicated / (sent - channel.lost) - 0.4) < 0.02
    delays = np.concatenate(delays)
    assert set(np.unique(delays)) == {2, 3, 4, 5}


def test_bad_streams_are_rejected_naming_them():
    trees = [sb.random_tree(4, 2, 0), sb.random_tree(3, 1, 1)]
    a, b = (t.n_modules for t in trees)
    with pytest.raises(ValueError, match=r"^streams\[0\]"):
        BusConfig(mode="async", streams=((0, 1),))
    with pytest.raises(TypeError, match=r"^streams\[1\]"):
        BusConfig(mode="async", streams=((a, 1), (b, 1.5)))
    with pytest.raises(TypeError, match="^streams"):
        BusConfig(mode="async", streams=5)
    with pytest.raises(ValueError, match=f"^bus: streams cover {a + b - 1} modules, the network has {a + b}"):
        AgentNetwork(trees, bus=BusConfig(mode="async", streams=((a, 1), (b - 1, 2))))
    with pytest.raises(ValueError, match="^bus: streams: modules .* linked"):
        AgentNetwork(trees, bus=BusConfig(mode="async", streams=((a - 1, 1), (b + 1, 2))))
    network = AgentNetwork(trees, bus=BusConfig(mode="async", streams=((a, 1), (b, 2))))
    with pytest.raises(ValueError, match="^bus: the streams cannot change"):
        network.reconfigure(BusConfig(mode="async", streams=((a, 1), (b, 3))))
