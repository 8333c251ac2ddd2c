"""One agent per SuperBot module, estimating the robot's mass properties from its neighbours only.

This is Moll, Will, Krivokon, Shen, "Distributed control of the center of mass of a modular robot"
(IROS 2006), Algorithms 1 and 2. Each agent n keeps, per connector i, an estimate ``E[n, i]`` of the mass
properties of everything beyond connector i, and its own mass properties ``O[n]`` (which depend on its three
joint angles, which it senses itself).

* Algorithm 1, UpdateMass(i, M): a message M arrives on connector i. It is expressed in the sender's
  connector frame; the receiver knows the relative rotation of the two mated connectors and turns it into
  its own connector frame. If it differs from ``E[n, i]`` it replaces it, and RecomputeMass runs.
* Algorithm 2, RecomputeMass: the total is ``T = O + sum_j E[n, j]``; on every connected connector i the
  agent sends ``T - E[n, i]`` (in that connector's frame), but only if it differs from what it last sent
  there.

All agents run in lock step, vectorised with numpy over agents and connectors (``round()``): a synchronous
round delivers every message sent in the previous round (Algorithm 1 for each), then runs Algorithm 2 for
every agent. Running Algorithm 2 for an agent whose inputs did not change is a no-op on the wire, because
messages are only sent when their payload changed; so this is the paper's event-driven algorithm, batched.

Numerics: "T minus what came from i" is computed as ``O + sum_{j != i} E[n, j]`` (prefix plus suffix sums
over the connectors). It is the same quantity, but it avoids subtracting nearly equal numbers, so the
value sent is bit-for-bit the same whenever the inputs are: once the estimates are right no rounding noise
triggers further messages, and the network falls silent. Estimates are stored in the receiving connector's
frame, so an agent moving its own joints keeps them valid and re-expresses them in its frame with its
current joint angles (tracking).

On top, as the paper suggests for world coordinates: a randomised leader election among the modules
touching the ground (each draws a random priority from the bus's seeded generator; the highest priority is
flooded through the tree), and propagation of the leader's world pose and support line outwards from the
leader, each agent composing the pose it received with its connector's pose. The connector through which
an agent heard of the leader (its *uplink*) tells it which side of each of its joints is fixed.

Speed: a round costs a fixed number of array operations whatever the number of agents (no Python loop
over agents, connectors or messages), each over all agents or connectors at once. The state is kept
component-major (components first, agents or connectors last, e.g. ``(13, N)``), so that every operation
runs along long contiguous rows, and per connector only for the connected ones (numbered 0..L-1 in the
order of their link number ``6 n + s``, the bus's address): when every agent is busy, as while the robot
moves, the arrays are used whole, without gathering. The (N, ...) attributes are views or copies of this
state. What never changes is tabled once: the mated connectors' relative rotations and the connector
frames are signed permutations (entries exactly 0 and +-1), so turning a message or a connector frame by
them is an exact gather with sign flips rather than a matrix product. The arithmetic is otherwise the
same operation for operation as the plain matrix formulation (see ``moments.transform_components``), so
results are reproducible bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

import legkit as lk
from legkit._validation import float_array, integer
from legkit.agents import moments
from legkit.agents.bus import BusConfig, Channel
from legkit.robots.superbot import CONNECTOR_BLOCK, ModelLayout, ModuleParameters, ModuleTree, module_kinematics_components

_N_SLOTS = 6
_UPLINK_BLOCK = np.append(CONNECTOR_BLOCK, -1)  # the block of each uplink connector; -1 for none (uplink -1)
_POSE_WIDTH = 9 + 3 + 3 + 3 + 1  # connector rotation, position, support point, support direction, leader id


@dataclass(frozen=True)
class GroundContact:
    """A module touching the ground: its ``block`` (0: A, 1: B) rests on the ground with world pose
    (``rotation``, ``translation``) of that block's frame (the module frame carried by the block), and the
    support line through ``line_point`` along ``line_direction`` (world, m) that the controller steers to."""

    module: int
    block: int
    rotation: np.ndarray
    translation: np.ndarray
    line_point: np.ndarray
    line_direction: np.ndarray


@dataclass(frozen=True)
class EstimateErrors:
    """Largest absolute errors of the agents' estimates against the centralised truth (module frames)."""

    mass: float
    com: float
    inertia: float

    @property
    def largest(self) -> float:
        """The largest of the three (kg, m and kg m^2 mixed: a convergence figure, not a physical one)."""
        return max(self.mass, self.com, self.inertia)


class AgentNetwork:
    """The agents of one or more module trees (``trees``), numbered tree after tree, and their bus.

    ``ground`` lists the modules touching the ground (candidates for leadership); ``angles`` (N, 3) are the
    joint angles the agents sense at start (zeros by default). On construction each agent runs Algorithm 2
    once with empty estimates (round 0: it sends its own mass on every connector).

    ``part_rotation``, ``part_translation``, ``part_moments`` and ``own`` are (N, ...) views of the agents'
    component-major state; ``connector_rotation``, ``connector_position`` and ``estimates_connector_frame``
    are computed (N, 6, ...) copies, as are the estimate queries below."""

    def __init__(
        self, trees: ModuleTree | Sequence[ModuleTree], bus: BusConfig | None = None, ground: Sequence[GroundContact] = (),
        angles: np.ndarray | None = None,
    ):
        trees = [trees] if isinstance(trees, ModuleTree) else list(trees)
        if not trees or not all(isinstance(t, ModuleTree) for t in trees):
            raise TypeError("trees: must be a ModuleTree or a non-empty sequence of ModuleTree")
        parameters = trees[0].parameters
        if any(t.parameters != parameters for t in trees):
            raise ValueError("trees: all trees must share the same ModuleParameters")
        bus = BusConfig() if bus is None else bus
        if not isinstance(bus, BusConfig):
            raise TypeError(f"bus: must be a BusConfig, got {type(bus).__name__}")
        self.parameters: ModuleParameters = parameters
        self.bus = bus
        connector_tables = [t.connector_table() for t in trees]
        offsets = np.cumsum([0] + [t.n_modules for t in trees])
        self.partner = np.concatenate([np.where(p >= 0, p + o, -1) for (p, _, _), o in zip(connector_tables, offsets)])
        self.partner_slot = np.concatenate([s for _, s, _ in connector_tables])
        self.mate = np.concatenate([m for _, _, m in connector_tables])
        self.connected = self.partner >= 0
        self.n_modules = int(offsets[-1])
        self.ground = self._check_ground(ground)
        self.rng = np.random.default_rng(bus.seed)
        self.mass_channel = Channel(self.partner, self.partner_slot, moments.WIDTH, bus, self.rng)
        self.election_channel = Channel(self.partner, self.partner_slot, 2, bus, self.rng)
        self.pose_channel = Channel(self.partner, self.partner_slot, _POSE_WIDTH, bus, self.rng)
        n = self.n_modules
        self.now = 0
        # Election: a random, distinct priority for each ground module; -1 means "no leader heard of".
        self.leader_key = np.full(n, -1.0)
        self.leader = np.full(n, -1, dtype=np.int64)
        self.uplink = np.full(n, -1, dtype=np.int64)
        priorities = self.rng.permutation(len(self.ground)).astype(float)
        for contact, priority in zip(self.ground, priorities):
            self.leader_key[contact.module], self.leader[contact.module] = priority, contact.module
        self.line = np.zeros((n, 6))
        for contact in self.ground:
            direction = np.asarray(contact.line_direction, dtype=float)
            self.line[contact.module] = np.concatenate([np.asarray(contact.line_point, dtype=float), direction / np.linalg.norm(direction)])
        # The ground contacts as arrays, and each module's contact (-1: not on the ground).
        self._contact_of_module = np.full(n, -1, dtype=np.int64)
        self._contact_of_module[[c.module for c in self.ground]] = np.arange(len(self.ground))
        self._contact_block = np.array([c.block for c in self.ground], dtype=np.int64)
        self._contact_rotation = np.array([np.asarray(c.rotation, dtype=float) for c in self.ground]).reshape(-1, 3, 3)
        self._contact_translation = np.array([np.asarray(c.translation, dtype=float) for c in self.ground]).reshape(-1, 3)
        # The connected connectors, numbered 0..L-1 in the order of their link numbers 6 n + s; number L stands
        # for any free connector (no estimate, no pose received).
        self._links = np.flatnonzero(self.connected)
        count = self._links.size
        self._link_module, self._link_slot = np.divmod(self._links, _N_SLOTS)
        self._index_of_link = np.full(n * _N_SLOTS, count)
        self._index_of_link[self._links] = np.arange(count)
        self._before, self._after = _other_connectors(self.connected, self._index_of_link)
        tables = _signed_permutation_tables(self.mate.reshape(-1, 3, 3)[self._links])
        self._mate_rotation_index, self._mate_rotation_signs = tables[0], tables[1]
        self._mate_moment_index, self._mate_moment_signs = np.ascontiguousarray(tables[2].T), np.ascontiguousarray(tables[3].T)
        # Estimates of what lies beyond each connector (13, L), in its frame, and Algorithm 2's copies in the
        # module frame (13, L + 1; free connectors: zeros).
        self._estimates = np.zeros((moments.WIDTH, count))
        self._module_frame_estimates = np.zeros((moments.WIDTH, count + 1))
        # Pose: the world pose of the uplink connector as received (receiver's connector frame), and the line;
        # the last pose message received on each connector (L + 1, 19), turned into the receiver's frame.
        self.received_connector_rotation = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        self.received_connector_position = np.zeros((n, 3))
        self.pose_known = np.zeros(n, dtype=bool)
        self._pose = np.zeros((count + 1, _POSE_WIDTH))
        self._pose[:, 18] = -1.0
        self._world_poses: tuple[np.ndarray, np.ndarray] | None = None  # every module's, while nothing changes
        self._dirty_mass = np.ones(n, dtype=bool)
        self._dirty_estimate = np.zeros(count, dtype=bool)  # the module-frame copy of an estimate is stale
        self._dirty_election = np.ones(n, dtype=bool)
        self._dirty_pose = np.ones(n, dtype=bool)
        self.recomputations = 0
        self._module_ids = np.arange(n)
        self._init_module_state(parameters)
        self._sense(self._checked_angles(np.zeros((n, 3)) if angles is None else angles), None)
        self._send()

    def _check_ground(self, ground: Sequence[GroundContact]) -> list[GroundContact]:
        checked = []
        for index, contact in enumerate(ground):
            if not isinstance(contact, GroundContact):
                raise TypeError(f"ground[{index}]: must be a GroundContact, got {type(contact).__name__}")
            if not 0 <= contact.module < self.n_modules or contact.block not in (0, 1):
                raise ValueError(f"ground[{index}]: module must be in 0..{self.n_modules - 1} and block 0 or 1")
            # Checked and copied: the network keeps its own, whatever the caller's arrays become.
            fields = {
                field: float_array(getattr(contact, field), f"ground[{index}].{field}", shape=shape, bound=1e6).copy()
                for field, shape in (("rotation", (3, 3)), ("translation", (3,)), ("line_point", (3,)), ("line_direction", (3,)))
            }
            if not np.linalg.norm(fields["line_direction"]) > 0:
                raise ValueError(f"ground[{index}]: line_direction must be a non-zero 3-vector")
            checked.append(replace(contact, **fields))
        if len({c.module for c in checked}) != len(checked):
            raise ValueError("ground: a module is listed twice")
        return checked

    def _init_module_state(self, parameters: ModuleParameters) -> None:
        """Each agent's own state, component-major, and the parts of it its joints never move: block A is the
        module frame, so its part moments and the frames of its connectors (0, 1, 2) are constants."""
        n = self.n_modules
        self.angles = np.zeros((n, 3))
        self._part_rotation = np.zeros((3, 3, 4, n))
        self._part_translation = np.zeros((3, 4, n))
        self._part_moments = np.zeros((moments.WIDTH, 4, n))
        self._own = np.zeros((moments.WIDTH, n))
        self._part_moments_zero = moments.pack(*_part_arrays(parameters)).T.copy()  # (13, 4)
        self._part_moments[:, 0] = moments.transform_components(np.eye(3), np.zeros(3), self._part_moments_zero[:, 0])[:, None]
        rotation_zero, position_zero = parameters.connector_frames()
        self._block_a_rotation = (np.eye(3) @ rotation_zero[:3]).transpose(1, 2, 0)  # (3, 3, slot)
        self._block_a_position = np.zeros((3, 1)) + moments.rotate_components(np.eye(3), position_zero[:3].T)  # (3, slot)
        # Block B's connectors (3, 4, 5) turn with part 3: their rotations are signed permutations of its columns.
        index, signs, _, _ = _signed_permutation_tables(rotation_zero[3:])
        self._block_b_columns = index.reshape(3, 3, 3)[:, 0] % 3  # (slot, j): the column of part 3 in column j
        self._block_b_signs = signs.reshape(3, 3, 3)[:, 0]  # (slot, j)
        self._block_b_position_zero = position_zero[3:].T  # (3, slot)
        # The frames of the connected connectors (3, 3, L + 1), (3, L + 1); free ones as connector 0 (A_end).
        a = self._link_slot < 3
        self._connector_rotation = np.empty((3, 3, self._links.size + 1))
        self._connector_position = np.empty((3, self._links.size + 1))
        self._connector_rotation[:, :, :-1][:, :, a] = self._block_a_rotation[:, :, self._link_slot[a]]
        self._connector_position[:, :-1][:, a] = self._block_a_position[:, self._link_slot[a]]
        self._connector_rotation[:, :, -1] = self._block_a_rotation[:, :, 0]
        self._connector_position[:, -1] = self._block_a_position[:, 0]
        # Block B's connected connectors: their number, module, and where their rotation's entries come from
        # in the part rotations (3, 3 x 4 parts x N): column j of part 3 of the module.
        self._block_b_connectors = (~a).nonzero()[0]
        self._block_b_module = self._link_module[~a]
        slot = self._link_slot[~a] - 3
        self._block_b_entries = self._block_b_columns[slot].T * (4 * n) + 3 * n + self._block_b_module  # (j, k)
        self._block_b_entry_signs = self._block_b_signs[slot].T  # (j, k)
        self._block_b_connector_position_zero = self._block_b_position_zero[:, slot]  # (3, k)

    # ------------------------------------------------------------------------------------------------
    # Each agent's own state, as (N, ...) arrays
    @property
    def part_rotation(self) -> np.ndarray:
        """(N, 4, 3, 3) rotations of each module's parts in its module frame (see ``module_kinematics``); a view."""
        return self._part_rotation.transpose(3, 2, 0, 1)

    @property
    def part_translation(self) -> np.ndarray:
        """(N, 4, 3) translations of each module's parts in its module frame, m; a view."""
        return self._part_translation.transpose(2, 1, 0)

    @property
    def part_moments(self) -> np.ndarray:
        """(N, 4, 13) packed moments of each module's parts, module frame; a view."""
        return self._part_moments.transpose(2, 1, 0)

    @property
    def own(self) -> np.ndarray:
        """(N, 13) packed moments of each module, module frame; a view."""
        return self._own.T

    @property
    def connector_rotation(self) -> np.ndarray:
        """(N, 6, 3, 3) rotations of each module's connector frames in its module frame (a copy)."""
        return self._connector_frames()[0].transpose(2, 3, 0, 1)

    @property
    def connector_position(self) -> np.ndarray:
        """(N, 6, 3) origins of each module's connector frames in its module frame, m (a copy)."""
        return self._connector_frames()[1].transpose(1, 2, 0)

    @property
    def estimates_connector_frame(self) -> np.ndarray:
        """(N, 6, 13) each agent's estimate of what lies beyond each connector, in that connector's frame (zeros
        on free connectors and before any message arrived; a copy)."""
        return self._by_connector(self._estimates)

    def _by_connector(self, estimates: np.ndarray) -> np.ndarray:
        """(N, 6, 13) from (13, L) per connected connector, zeros on the free ones."""
        full = np.zeros((moments.WIDTH, self.n_modules * _N_SLOTS))
        full[:, self._links] = estimates
        return full.reshape(moments.WIDTH, self.n_modules, _N_SLOTS).transpose(1, 2, 0)

    def _connector_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Every connector's frame, connected or not: rotations (3, 3, N, 6) and positions (3, N, 6)."""
        n = self.n_modules
        rotation = np.empty((3, 3, n, _N_SLOTS))
        position = np.empty((3, n, _N_SLOTS))
        rotation[:, :, :, :3] = self._block_a_rotation[:, :, None]
        position[:, :, :3] = self._block_a_position[:, None]
        block_b = self._part_rotation[:, :, 3]  # (3, 3, N)
        turned = block_b[:, self._block_b_columns] * self._block_b_signs[..., None]  # (3, slot, 3, N)
        turned += 0.0
        rotation[:, :, :, 3:] = turned.transpose(0, 2, 3, 1)
        turned_position = self._part_translation[:, 3, None] + moments.rotate_components(block_b[:, :, None], self._block_b_position_zero[..., None])
        position[:, :, 3:] = turned_position.transpose(0, 2, 1)
        return rotation, position

    # ------------------------------------------------------------------------------------------------
    # Sensing
    def observe(self, angles: np.ndarray) -> None:
        """Every agent reads its own three joint angles (N, 3) rad. Agents whose angles changed recompute their
        own mass properties and connector poses, and will run Algorithm 2 in the next round."""
        angles = self._checked_angles(angles)
        changed = (angles != self.angles).any(axis=1)
        if changed.all():
            self._sense(angles, None)
        elif changed.any():
            self._sense(angles, changed)

    def _checked_angles(self, angles: np.ndarray) -> np.ndarray:
        return float_array(angles, "angles", shape=(self.n_modules, 3))

    def _sense(self, angles: np.ndarray, changed: np.ndarray | None) -> None:
        """The agents ``changed`` (N,) (all if None) take their ``angles``: part poses and moments, own mass, and
        the frames of block B's connected connectors."""
        rows = slice(None) if changed is None else changed.nonzero()[0]
        self.angles[rows] = angles[rows]
        rotation, translation = module_kinematics_components(angles[rows], self.parameters)
        self._part_rotation[..., rows] = rotation
        self._part_translation[..., rows] = translation
        parts = moments.transform_components(rotation[:, :, 1:], translation[:, 1:], self._part_moments_zero[:, 1:, None])
        self._part_moments[:, 1:, rows] = parts
        own = self._part_moments[:, 0, :1] + parts[:, 0]
        own += parts[:, 1]
        own += parts[:, 2]
        own += 0.0  # sums from +0, as numpy's reduction over the parts did
        self._own[:, rows] = own
        connectors, module = self._block_b_connectors, self._block_b_module
        entries, signs, position_zero = self._block_b_entries, self._block_b_entry_signs, self._block_b_connector_position_zero
        if changed is not None:
            moved = changed.take(module)
            connectors, module = connectors[moved], module[moved]
            entries, signs, position_zero = entries[:, moved], signs[:, moved], position_zero[:, moved]
        turned = self._part_rotation.reshape(3, -1).take(entries, axis=1)  # (3, 3, k)
        turned *= signs
        turned += 0.0  # the matrix product this replaces gives +0.0 where the sign flip gives -0.0
        self._connector_rotation[:, :, connectors] = turned
        block_b = self._part_rotation[:, :, 3].take(module, axis=2)
        position = moments.rotate_components(block_b, position_zero)
        position += self._part_translation[:, 3].take(module, axis=1)
        self._connector_position[:, connectors] = position
        self._dirty_mass[rows] = True
        if changed is None:
            self._dirty_estimate[:] = True
        else:
            self._dirty_estimate |= changed.take(self._link_module)
        self._dirty_pose[rows] = True
        self._world_poses = None

    def reconfigure(self, bus: BusConfig) -> None:
        """Change the network's behaviour from now on (delays, loss, duplication, retransmission period), e.g.
        to stop losses; messages in flight keep their delivery times. The mode cannot change."""
        if not isinstance(bus, BusConfig):
            raise TypeError(f"bus: must be a BusConfig, got {type(bus).__name__}")
        if bus.mode != self.bus.mode:
            raise ValueError(f"bus: the mode cannot change from {self.bus.mode!r} to {bus.mode!r}")
        self.bus = bus
        for channel in self.channels:
            channel.config = bus

    # ------------------------------------------------------------------------------------------------
    # Rounds
    def round(self) -> int:
        """One tick: deliver due messages (Algorithm 1), then Algorithm 2 and the election / pose updates for
        every agent. Returns the number of data messages put on the wire this round (all channels)."""
        before = self.transmissions
        self.now += 1
        self._receive()
        self._send()
        for channel in self.channels:
            channel.retransmit(self.now)
        return self.transmissions - before

    def run(self, rounds: int) -> int:
        """Run ``rounds`` (>= 0) rounds; returns the data messages sent."""
        if integer(rounds, "rounds") < 0:
            raise ValueError(f"rounds: must be >= 0, got {rounds}")
        return sum(self.round() for _ in range(rounds))

    def run_until_quiescent(self, max_rounds: int = 100_000) -> int:
        """Run rounds until every channel is idle (nothing in flight, nothing unacknowledged); returns the
        rounds run. Raises RuntimeError if that takes more than ``max_rounds`` (>= 0)."""
        if integer(max_rounds, "max_rounds") < 0:
            raise ValueError(f"max_rounds: must be >= 0, got {max_rounds}")
        for rounds in range(max_rounds + 1):
            if self.quiescent:
                return rounds
            self.round()
        raise RuntimeError(f"max_rounds: the network did not fall silent within {max_rounds} rounds")

    @property
    def channels(self) -> tuple[Channel, Channel, Channel]:
        return self.mass_channel, self.election_channel, self.pose_channel

    @property
    def quiescent(self) -> bool:
        """No agent has work pending (joints moved since the last round), nothing is on the wire and nothing
        waits for an acknowledgement, on every channel."""
        pending = self._dirty_mass.any() or self._dirty_election.any() or self._dirty_pose.any()
        return not pending and all(c.idle for c in self.channels)

    @property
    def transmissions(self) -> int:
        """Data messages put on the wire so far (all channels, including retransmissions)."""
        return sum(c.transmissions for c in self.channels)

    @property
    def acknowledgements(self) -> int:
        """Acknowledgements put on the wire so far (asynchronous mode only)."""
        return sum(c.acknowledgements for c in self.channels)

    def _receive(self) -> None:
        self._world_poses = None
        # Algorithm 1: into the receiving connector's frame (mated connectors share their origin); an agent
        # whose estimate changed runs Algorithm 2 in this round's _send.
        links, _, payload = self.mass_channel._deliver(self.now)
        connector = self._index_of_link.take(links)
        count = links.size
        columns = np.ascontiguousarray(payload.T).reshape(-1)  # component-major: component c of message j at c count + j
        received = columns.take(self._mate_moment_index.take(connector, axis=1) * count + np.arange(count))
        received *= self._mate_moment_signs.take(connector, axis=1)
        received[1:] += 0.0  # the turned moments the arithmetic gave: +0.0 where the sign flip gives -0.0
        changed = (received != self._estimates.take(connector, axis=1)).any(axis=0)
        if not changed.all():
            connector, received = connector[changed], received[:, changed]
        self._estimates[:, connector] = received
        self._dirty_mass[self._link_module.take(connector)] = True
        self._dirty_estimate[connector] = True

        links, _, payload = self.election_channel._deliver(self.now)
        if links.size:
            module, slot = np.divmod(links, _N_SLOTS)
            key = payload[:, 0]
            best = self.leader_key.copy()
            np.maximum.at(best, module, key)
            improved = (key == best[module]) & (key > self.leader_key[module])
            module, slot = module[improved], slot[improved]
            self.leader_key[module] = key[improved]
            self.leader[module] = payload[improved, 1].astype(np.int64)
            self.uplink[module] = slot
            self._dirty_election[module] = True
            self._dirty_pose[module] = True

        # Poses are kept per connector (a pose may arrive before the election tells which connector leads to
        # the leader); an agent uses the one on its uplink, if it comes from the leader it follows.
        links, _, payload = self.pose_channel._deliver(self.now)
        connector = self._index_of_link.take(links)
        turned = payload.reshape(-1).take(self._mate_rotation_index.take(connector, axis=0) + _POSE_WIDTH * np.arange(links.size)[:, None])
        turned *= self._mate_rotation_signs.take(connector, axis=0)
        turned += 0.0
        payload[:, :9] = turned
        self._pose[connector] = payload
        module, slot = np.divmod(links, _N_SLOTS)
        self._dirty_pose[module[slot == self.uplink.take(module)]] = True
        uplink = self._pose.take(self._index_of_link.take(self._module_ids * _N_SLOTS + np.maximum(self.uplink, 0)), axis=0)
        self.pose_known = (self.uplink >= 0) & (uplink[:, 18] == self.leader)
        self.received_connector_rotation = uplink[:, :9].reshape(-1, 3, 3)
        self.received_connector_position = uplink[:, 9:12]
        follower = ~self._is_leader()
        self.line[follower] = uplink[follower, 12:18]

    def _send(self) -> None:
        # Algorithm 2 for every agent whose own mass or an estimate changed.
        dirty, self._dirty_mass = self._dirty_mass, np.zeros(self.n_modules, dtype=bool)
        self.recomputations += int(np.count_nonzero(dirty))
        if self._dirty_estimate.all():
            self._module_frame_estimates[:, :-1] = moments.transform_components(
                self._connector_rotation[:, :, :-1], self._connector_position[:, :-1], self._estimates
            )
        else:
            stale = self._dirty_estimate.nonzero()[0]
            self._module_frame_estimates[:, stale] = moments.transform_components(
                self._connector_rotation.take(stale, axis=2), self._connector_position.take(stale, axis=1), self._estimates.take(stale, axis=1)
            )
        self._dirty_estimate[:] = False
        active = dirty.take(self._link_module)
        if active.all():
            links, module, before, after = self._links, self._link_module, self._before, self._after
            rotation, position = self._connector_rotation[:, :, :-1], self._connector_position[:, :-1]
        else:
            connector = active.nonzero()[0]
            links, module, before, after = self._links[connector], self._link_module[connector], self._before[:, connector], self._after[:, connector]
            rotation, position = self._connector_rotation.take(connector, axis=2), self._connector_position.take(connector, axis=1)
        outgoing = self._own.take(module, axis=1)
        outgoing += self._others(before, after)
        inverse_translation = moments.inverse_translation_components(rotation, position)
        message = moments.transform_components(rotation.swapaxes(0, 1), inverse_translation, outgoing)
        self.mass_channel._send_changed(self.now, links, message.T)

        # Flooding: forward the best leader heard of on every connector but the one it came from.
        ready = self._dirty_election & (self.leader_key >= 0)
        self._dirty_election[:] = False
        if ready.any():
            links = self._links[self._forward(ready)]
            module = links // _N_SLOTS
            self.election_channel._send_changed(self.now, links, np.stack([self.leader_key[module], self.leader[module]], axis=-1))

        ready = self._dirty_pose & (self.pose_known | self._is_leader())
        self._dirty_pose[:] = False
        connector = self._forward(ready).nonzero()[0]
        links, module = self._links.take(connector), self._link_module.take(connector)
        if ready.all():
            rotation, translation = self._world_poses_of(self._module_ids)
            rotation, translation = rotation.take(module, axis=0), translation.take(module, axis=0)
        else:
            rotation, translation = self._compute_world_poses(module)
        payload = np.empty((links.size, _POSE_WIDTH))
        frame = np.ascontiguousarray(self._connector_rotation.take(connector, axis=2).transpose(2, 0, 1))
        np.matmul(rotation, frame, out=payload[:, :9].reshape(-1, 3, 3))
        origin = moments.rotate_components(rotation.transpose(1, 2, 0), self._connector_position.take(connector, axis=1))
        payload[:, 9:12] = translation + origin.T
        payload[:, 12:18] = self.line.take(module, axis=0)
        payload[:, 18] = self.leader.take(module)
        self.pose_channel._send_changed(self.now, links, payload)

    def _others(self, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """(13, k) sums of the module-frame estimates of the other connected connectors of k connectors, given as
        lists (P, k) of the connectors before and after each one's own, padded with free (zero) connectors.

        "T minus what came from i" as prefix plus suffix sums over the connectors (no subtraction, a fixed
        order): the slots below i upwards from +0, plus the slots above i downwards from +0. Free connectors,
        whose estimates are zero, leave these sums unchanged, so only the connected ones are listed."""
        estimates = self._module_frame_estimates
        prefix = np.zeros((moments.WIDTH, before.shape[1]))
        suffix = np.zeros((moments.WIDTH, before.shape[1]))
        for k in range(before.shape[0]):
            prefix += estimates.take(before[k], axis=1)
            suffix += estimates.take(after[k], axis=1)
        return np.add(prefix, suffix, out=prefix)

    def _forward(self, ready: np.ndarray) -> np.ndarray:
        """(L,) True for the connected connectors of the agents ``ready`` (N,) other than their uplinks."""
        module = self._link_module
        return ready.take(module) & (self._link_slot != self.uplink.take(module))

    # ------------------------------------------------------------------------------------------------
    # What each agent knows
    def _is_leader(self) -> np.ndarray:
        """(N,) True for the agents that currently believe they lead (a ground module that heard of no better)."""
        return self.leader == self._module_ids

    def connector_estimates(self) -> np.ndarray:
        """Packed moments (N, 6, 13) of what lies beyond each connector, in each agent's module frame at its
        current joint angles (zeros on free connectors and before any message arrived)."""
        rotation, position = self._connector_frames()
        estimates = self._by_connector(self._estimates).transpose(2, 0, 1)
        return moments.transform_components(rotation, position, estimates).transpose(1, 2, 0)

    def current_connector_estimates(self) -> np.ndarray:
        """Like ``connector_estimates`` (N, 6, 13), read from the copies Algorithm 2 keeps: current after
        ``round()`` (``observe`` without a round leaves them at the previous angles)."""
        return self._by_connector(self._module_frame_estimates[:, :-1])

    def block_estimates(self) -> np.ndarray:
        """(N, 2, 13) the sums of ``current_connector_estimates`` over each block's connectors: what lies beyond
        block A (connectors 0, 1, 2) and beyond block B (3, 4, 5), summed in connector order."""
        estimates = self._module_frame_estimates
        connector = self._index_of_link.reshape(self.n_modules, _N_SLOTS).T  # (slot, N); free: the zero column
        sums = np.empty((2, moments.WIDTH, self.n_modules))
        for block in range(2):
            total = sums[block]
            np.add(estimates.take(connector[3 * block], axis=1), estimates.take(connector[3 * block + 1], axis=1), out=total)
            total += estimates.take(connector[3 * block + 2], axis=1)
            total += 0.0  # sums from +0, as numpy's reduction does
        return sums.transpose(2, 0, 1)

    def total_estimates(self) -> np.ndarray:
        """Packed moments (N, 13) of the whole robot (as each agent knows it), in each agent's module frame."""
        return self.own + self.connector_estimates().sum(axis=1)

    def world_poses(self, modules: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Each agent's belief of its module frame's world pose: rotations (k, 3, 3), translations (k, 3) for
        ``modules`` (all by default).

        Leaders compute it from their ground contact and joint angles; the others from the pose received on
        their uplink composed with that connector's current pose. Identity where nothing is known yet
        (``pose_known`` False and not a leader)."""
        if modules is None:
            rotation, translation = self._world_poses_of(self._module_ids)
            return rotation.copy(), translation.copy()
        return self._world_poses_of(np.asarray(modules, dtype=np.int64))

    def _world_poses_of(self, modules: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``world_poses(modules)``. Every module's is kept from when it is first asked for until the joints
        move or messages arrive (a round's pose messages and the controller after it ask for the same)."""
        if self._world_poses is None and modules.size == self.n_modules:
            self._world_poses = self._compute_world_poses(self._module_ids)
        if self._world_poses is None:
            return self._compute_world_poses(modules)
        rotation, translation = self._world_poses
        return rotation[modules], translation[modules]

    def _compute_world_poses(self, modules: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # The uplink connector's frame; an agent without an uplink uses connector 0's (the result is replaced).
        uplink = self._index_of_link.take(modules * _N_SLOTS + np.maximum(self.uplink.take(modules), 0))
        connector = self._connector_rotation.take(uplink, axis=2)
        inverse_translation = moments.inverse_translation_components(connector, self._connector_position.take(uplink, axis=1))
        received = self.received_connector_rotation.take(modules, axis=0)
        rotation = received @ np.ascontiguousarray(connector.transpose(2, 0, 1)).swapaxes(1, 2)
        translation = moments.rotate_components(received.transpose(1, 2, 0), inverse_translation).T
        translation += self.received_connector_position.take(modules, axis=0)
        is_leader = self.leader.take(modules) == modules
        leaders = is_leader.nonzero()[0]
        if leaders.size:
            contact = self._contact_of_module.take(modules.take(leaders))
            rotation[leaders] = self._contact_rotation[contact]
            translation[leaders] = self._contact_translation[contact]
            # A leader standing on block B: the block's pose composed with the inverse of part 3's.
            on_b = self._contact_block[contact] == 1
            if on_b.any():
                n = modules[leaders[on_b]]
                block_rotation, block_translation = self._contact_rotation[contact[on_b]], self._contact_translation[contact[on_b]]
                part_inverse_rotation, part_inverse_translation = moments.inverse_pose(
                    np.ascontiguousarray(self.part_rotation[n, 3]), self.part_translation[n, 3]
                )
                rotation[leaders[on_b]] = block_rotation @ part_inverse_rotation
                translation[leaders[on_b]] = block_translation + (block_rotation @ part_inverse_translation[..., None])[..., 0]
        unknown = ~(self.pose_known.take(modules) | is_leader)
        if unknown.any():
            rotation[unknown] = np.eye(3)
            translation[unknown] = 0.0
        return rotation, translation

    def fixed_block(self) -> np.ndarray:
        """(N,) the block (0: A, 1: B) on the leader's side of each module: the grounded block for a leader, the
        block of the uplink connector otherwise; -1 where no leader is known."""
        block = _UPLINK_BLOCK.take(self.uplink)
        leaders = self._is_leader().nonzero()[0]
        block[leaders] = self._contact_block.take(self._contact_of_module.take(leaders))
        return block

    # ------------------------------------------------------------------------------------------------
    # Reports against the centralised truth
    def estimate_errors(self, model: lk.Model, layout: ModelLayout, q: np.ndarray) -> EstimateErrors:
        """Largest errors of every agent's per-connector and total estimates against
        ``lk.subtree_mass_properties(model, q)``, compared in each module's frame (true module poses)."""
        reference_connectors, reference_totals = reference_estimates(model, layout, self.partner, q)
        mine = unpack_pairs(self.connector_estimates()[self.connected], self.total_estimates())
        truth = unpack_pairs(reference_connectors[self.connected], reference_totals)
        return EstimateErrors(*(float(np.max(np.abs(a - b))) for a, b in zip(mine, truth)))


def unpack_pairs(connector_moments: np.ndarray, total_moments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Connector and total estimates unpacked and concatenated: (masses, COMs, inertias)."""
    a = moments.unpack(connector_moments)
    b = moments.unpack(total_moments)
    return np.concatenate([a[0], b[0]]), np.concatenate([a[1], b[1]]), np.concatenate([a[2], b[2]])


def reference_estimates(model: lk.Model, layout: ModelLayout, partner: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The centralised truth from ``lk.subtree_mass_properties``: packed moments of what lies beyond each
    connector (N, 6, 13) and of each module's whole tree (N, 13), in each module's frame at configuration q.

    Beyond a connector leading away from the root lies the child module's subtree; beyond the connector
    leading to the root lies the whole tree minus the module's own subtree."""
    mass, com, inertia = lk.subtree_mass_properties(model, q)
    subtree = moments.pack(mass, com, inertia)  # world frame, per body
    entry = layout.part_bodies.min(axis=1)  # the first body of each module (the one hanging off its parent)
    parents = np.asarray(model.parents)
    n_modules = partner.shape[0]
    module_of_body = np.full(model.nbodies, -1, dtype=np.int64)
    module_of_body[layout.part_bodies] = np.arange(n_modules)[:, None]
    parent_module = module_of_body[parents[entry]]
    tree_total = subtree[entry[layout.root_modules[layout.tree_of_module]]]
    own_subtree = subtree[entry]
    beyond = np.zeros(partner.shape + (moments.WIDTH,))
    connected = partner >= 0
    rows, slots = np.nonzero(connected)
    other = partner[rows, slots]
    toward_root = parent_module[rows] == other
    beyond[rows, slots] = np.where(toward_root[:, None], tree_total[rows] - own_subtree[rows], own_subtree[other])
    rotation, translation = layout.module_poses(model, q)
    inverse_rotation, inverse_translation = moments.inverse_pose(rotation, translation)
    beyond = np.where(connected[..., None], moments.transform(inverse_rotation[:, None], inverse_translation[:, None], beyond), 0.0)
    return beyond, moments.transform(inverse_rotation, inverse_translation, tree_total)


def _other_connectors(connected: np.ndarray, index_of_link: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each connected connector (by number), the numbers of its module's other connected connectors: those
    with a lower slot in ascending order, and those with a higher slot in descending order, (P, L) each,
    padded with the number of a free connector (P: the most connectors of a module, less one)."""
    n, slots = connected.shape
    padding = int(connected.sum())
    width = max(int(connected.sum(axis=1).max()) - 1, 0)
    before, after = [], []
    for module, slot in zip(*np.nonzero(connected)):
        others = [(j, int(index_of_link[module * slots + j])) for j in np.flatnonzero(connected[module])]
        below = [c for j, c in others if j < slot]
        above = [c for j, c in reversed(others) if j > slot]
        before.append(below + [padding] * (width - len(below)))
        after.append(above + [padding] * (width - len(above)))
    shape = (len(before), width)
    return np.array(before, dtype=np.int64).reshape(shape).T.copy(), np.array(after, dtype=np.int64).reshape(shape).T.copy()


def _part_arrays(parameters: ModuleParameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mass (4,), COM (4, 3), inertia about the COM (4, 3, 3)) of the module's parts, zero-angle module frame."""
    parts = parameters.part_mass_properties()
    return np.array([p.mass for p in parts]), np.array([p.com for p in parts]), np.array([p.inertia for p in parts])


def _signed_permutation_tables(rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gather tables for signed permutation matrices ``rotation`` (..., 3, 3) (entries exactly 0 and +-1).

    Returns (index (..., 9), signs (..., 9)) with ``(A @ R).flat[f] = signs[f] * A.flat[index[f]]``, and
    (index (..., 13), signs (..., 13)) with ``transform(R, 0, x) = signs * x[index]`` for packed moments x
    (the second moment's lower triangle taken from its upper one, as ``transform`` does). Exact up to the
    sign of zero (the products give +0.0 where a sign flip gives -0.0; callers add 0.0)."""
    source_row = np.argmax(np.abs(rotation), axis=-2)  # column j of R has its entry in row source_row[j]
    column_signs = np.take_along_axis(rotation, source_row[..., None, :], axis=-2)[..., 0, :]
    source_column = np.argmax(np.abs(rotation), axis=-1)  # row i of R has its entry in column source_column[i]
    row_signs = np.take_along_axis(rotation, source_column[..., :, None], axis=-1)[..., 0]
    i, j = np.divmod(np.arange(9), 3)
    product_index = 3 * i + source_row[..., j]
    product_signs = column_signs[..., j]
    low, high = np.minimum(i, j), np.maximum(i, j)
    moment_index = np.concatenate(
        [np.zeros(rotation.shape[:-2] + (1,), dtype=np.int64), 1 + source_column, 4 + 3 * source_column[..., low] + source_column[..., high]], axis=-1
    )
    moment_signs = np.concatenate([np.ones(rotation.shape[:-2] + (1,)), row_signs, row_signs[..., low] * row_signs[..., high]], axis=-1)
    return product_index, product_signs, moment_index, moment_signs
