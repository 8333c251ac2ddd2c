"""SuperBot modules, trees of modules, and their legkit models.

A SuperBot module (Shen, Krivokon, Chiu, Everist, Rubenstein, Venkatesh, "SuperBot: A Deployable,
Multi-Functional, and Modular Self-Reconfigurable Robotic System", IROS 2006) is two cubic end blocks joined
by three revolute joints: pitch, roll about the module's long axis, pitch. It has six genderless connectors,
three per end block, and two connectors mate face to face at 0, 90, 180 or 270 degrees about the face normal.

Module frame (also each agent's own frame, see ``legkit.agents``): rigidly attached to end block A, origin at
the centre of A's end face, z along the long axis towards block B, x along the pitch axes. At zero joint
angles the module is a straight ``w x w x 2w`` cuboid (``w`` = ``MODULE_WIDTH``) occupying z in [0, 2w].
The module is split into four rigid parts along z, with mass proportional to length:

    part 0  block A     z in [0, 0.75 w]       joint 1 (pitch, axis x) at z = 0.75 w
    part 1  link 1      z in [0.75 w, w]       joint 2 (roll, axis z)  at z = w
    part 2  link 2      z in [w, 1.25 w]       joint 3 (pitch, axis x) at z = 1.25 w
    part 3  block B     z in [1.25 w, 2 w]

Joint angle ``phi_k`` is the right-handed rotation of the B-side parts relative to the A-side parts about
the joint's axis (positive x for the pitches, positive z for the roll), in radians.

Connectors (frame: origin at the face centre, z = outward face normal, x = module x):

    0 A_end  (0, 0, 0)        normal -z       3 B_end  (0, 0, 2w)       normal +z
    1 A_left (0, w/2, w/2)    normal +y       4 B_left (0, w/2, 3w/2)   normal +y
    2 A_right (0, -w/2, w/2)  normal -y       5 B_right (0, -w/2, 3w/2) normal -y

Two connectors ``a`` (of module u) and ``b`` (of module v) mated at angle ``alpha`` have coincident origins and
opposite normals; ``b``'s frame in ``a``'s frame is ``Rz(alpha) Rx(pi)``. This matrix is its own inverse
(``(Rz(alpha) Rx(pi))^2 = I``), so a connection looks the same from both sides, as genderless connectors should.

Default figures (approximate; the published SuperBot module is about 84 mm x 84 mm x 168 mm and weighs about
0.5 kg): ``MODULE_WIDTH = 0.084`` m and ``REAL_MODULE_MASS = 0.5`` kg. The seed experiment (Moll et al.,
IROS 2006) simulates modules at 10 % of the real mass, so ``MODULE_MASS = 0.05`` kg. Joint limits are taken
as +-90 degrees for all three joints (approximate).

Every joint is driven by a geared servo: the model carries its reflected rotor inertia (``Model.armature``,
``SERVO_ARMATURE`` = 0.01 kg m^2) and viscous back-EMF damping (``Model.damping``, ``SERVO_DAMPING`` =
0.1 N m s/rad), the order of magnitude of a small geared servo (rotor ~2e-7 kg m^2 behind a ~1:250 gearbox;
~1 N m stall torque over ~6 rad/s no-load speed): approximate figures, not SuperBot's datasheet. Without
them the seed's 5 g middle links under K_P = 10 N m/rad would ring at ~1.4e3 rad/s, beyond what a 1 kHz
torque loop can control. The servo's motor cannot exceed its stall torque: ``SERVO_TORQUE_LIMIT`` = 1 N m
(the same figure) bounds every commanded joint torque (``ModuleParameters.servo_torque_limit``; the balance
experiment clips its controllers' torques to it). The seed simulates modules at 10 % of the real mass so
that such motors can lift long chains [Moll 2006, Sect. V].
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

import legkit as lk
from legkit._validation import float_array, instance, integer, is_real, parameter_fields

MODULE_WIDTH = 0.084
REAL_MODULE_MASS = 0.5
SIMULATED_MASS_FRACTION = 0.1
MODULE_MASS = REAL_MODULE_MASS * SIMULATED_MASS_FRACTION
JOINT_LIMIT = np.pi / 2
SERVO_ARMATURE = 0.01
SERVO_DAMPING = 0.1
SERVO_TORQUE_LIMIT = 1.0
#: Modules a random tree may have: past a few hundred, the branches box themselves in on the module lattice and
#: every placement attempt fails (1,000 fails for every seed tried, after about 5 s).
MAX_RANDOM_MODULES = 1000

CONNECTOR_NAMES = ("A_end", "A_left", "A_right", "B_end", "B_left", "B_right")
CONNECTOR_BLOCK = np.array([0, 0, 0, 1, 1, 1])  # 0: on block A (part 0), 1: on block B (part 3)
ANGLES_DEG = (0, 90, 180, 270)
JOINT_NAMES = ("pitch1", "roll", "pitch2")
# Unit joint axes in the module frame at zero angles, and the parts' z-extents in module widths.
JOINT_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
JOINT_Z = np.array([0.75, 1.0, 1.25])
PART_Z = np.array([[0.0, 0.75], [0.75, 1.0], [1.0, 1.25], [1.25, 2.0]])


def rot_x(angle: float | np.ndarray) -> np.ndarray:
    """Rotation matrices about x by ``angle`` (radians); shape ``angle.shape + (3, 3)``."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_z(angle: float | np.ndarray) -> np.ndarray:
    """Rotation matrices about z by ``angle`` (radians); shape ``angle.shape + (3, 3)``."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


_MATE_ROTATIONS = {angle: np.round(rot_z(np.radians(angle)) @ rot_x(np.pi)) for angle in ANGLES_DEG}


def mate_rotation(angle_deg: int) -> np.ndarray:
    """Rotation of a mated connector's frame in its partner connector's frame: ``Rz(angle) Rx(pi)`` (3, 3).

    Entries are exact integers (the angles are multiples of 90 degrees)."""
    if angle_deg not in _MATE_ROTATIONS:
        raise ValueError(f"angle_deg: must be one of {ANGLES_DEG}, got {angle_deg!r}")
    return _MATE_ROTATIONS[angle_deg].copy()


@dataclass(frozen=True)
class ModuleParameters:
    """Size and mass of one module: ``width`` (m, the end blocks' edge) and ``mass`` (kg, whole module); its
    joints' ``joint_limit`` (rad) and servos' ``servo_armature`` (kg m^2), ``servo_damping`` (N m s/rad) and
    ``servo_torque_limit`` (N m, the largest torque a servo applies; inf for none)."""

    width: float = MODULE_WIDTH
    mass: float = MODULE_MASS
    joint_limit: float = JOINT_LIMIT
    servo_armature: float = SERVO_ARMATURE
    servo_damping: float = SERVO_DAMPING
    servo_torque_limit: float = SERVO_TORQUE_LIMIT

    def __post_init__(self) -> None:
        parameter_fields(self, positive=("width", "mass", "joint_limit"), non_negative=("servo_armature", "servo_damping"))
        if not is_real(self.servo_torque_limit) or not float(self.servo_torque_limit) > 0:  # NaN fails too; inf: no limit
            raise ValueError(f"servo_torque_limit: must be > 0 (inf for none), got {self.servo_torque_limit!r}")

    @property
    def joint_points(self) -> np.ndarray:
        """(3, 3) joint axis points in the module frame at zero angles (m)."""
        return np.outer(JOINT_Z, [0.0, 0.0, self.width])

    def part_mass_properties(self) -> list[lk.MassProperties]:
        """The four parts (block A, link 1, link 2, block B) as solid boxes, in the module frame at zero angles."""
        w = self.width
        parts = []
        for z0, z1 in PART_Z:
            length = (z1 - z0) * w
            parts.append(lk.MassProperties.solid_box(self.mass * (z1 - z0) / 2.0, [w, w, length], center=[0, 0, 0.5 * (z0 + z1) * w]))
        return parts

    def connector_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(rotations (6, 3, 3), positions (6, 3)) of the connectors in the module frame at zero angles."""
        w = self.width
        positions = np.array([[0, 0, 0], [0, w / 2, w / 2], [0, -w / 2, w / 2], [0, 0, 2 * w], [0, w / 2, 1.5 * w], [0, -w / 2, 1.5 * w]])
        normals = np.array([[0, 0, -1], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 1, 0], [0, -1, 0]], dtype=float)
        x_axes = np.tile([1.0, 0.0, 0.0], (6, 1))
        rotations = np.stack([x_axes, np.cross(normals, x_axes), normals], axis=-1)
        return rotations, positions


def module_kinematics(angles: np.ndarray, parameters: ModuleParameters) -> tuple[np.ndarray, np.ndarray]:
    """Poses of the four parts in the module frame for joint angles ``angles`` (..., 3) in radians.

    Returns (rotations (..., 4, 3, 3), translations (..., 4, 3)): part j's points map as x_module = R x + t,
    where x is the point's position in the module frame at zero angles. Part k + 1 is part k turned by joint
    k about its point p_k (zero-angle coordinates): x -> R_k (J_k (x - p_k) + p_k) + t_k."""
    rotations, translations = module_kinematics_components(angles, parameters)
    return np.moveaxis(rotations, (0, 1, 2), (-2, -1, -3)), np.moveaxis(translations, (0, 1), (-1, -2))


def module_kinematics_components(angles: np.ndarray, parameters: ModuleParameters) -> tuple[np.ndarray, np.ndarray]:
    """``module_kinematics`` component-major: rotations (3, 3, 4, ...) and translations (3, 4, ...) for angles
    (..., 3), components first and the batch last (long rows: much faster for many modules)."""
    angles = np.asarray(angles, dtype=float)
    batch = angles.shape[:-1]
    count = math.prod(batch)
    trig = np.empty((2, 3, count))  # cos, sin of the three angles
    np.cos(angles.reshape(count, 3).T, out=trig[0])
    np.sin(angles.reshape(count, 3).T, out=trig[1])
    (cos, sin), minus_sin = trig, -trig[1]
    # Parts 1 and 2, Rx(phi_1) and Rx(phi_1) Rz(phi_2), written out: every entry is a single product (+0.0
    # turns the -0.0 of a zero angle into +0.0, as the matrix product did).
    products = trig[:, 0, None] * trig[::-1, 1]  # c1 s2, c1 c2; s1 s2, s1 c2
    entries = np.concatenate([cos[:2], sin[:1], minus_sin[:2], products.reshape(4, count)])
    entries += 0.0
    rotations: np.ndarray = np.zeros((9, 4, count))
    rotations[_IDENTITY_ENTRIES, 0] = 1.0
    rotations[0, 1] = 1.0
    rotations[_PART_1_2_ENTRIES[0], _PART_1_2_ENTRIES[1]] = entries[_PART_1_2_VALUES]
    rotations = rotations.reshape(3, 3, 4, count)
    # Part 3 = part 2 Rx(phi_3): a matrix product (its rounding is the BLAS kernel's), on contiguous matrices;
    # Rx(phi_3) exactly as ``rot_x`` builds it.
    third_joint = np.zeros((count, 9))
    third_joint[:, 0] = 1.0
    third_joint[:, 4], third_joint[:, 5], third_joint[:, 7], third_joint[:, 8] = cos[2], minus_sin[2], sin[2], cos[2]
    second = np.ascontiguousarray(rotations[:, :, 2].transpose(2, 0, 1))
    rotations[:, :, 3] = (second @ third_joint.reshape(count, 3, 3)).transpose(1, 2, 0)
    # t_{k+1} = t_k + (R_k - R_{k+1}) p_k from t_0 = +0; the joint points lie on the z axis, so each step is a
    # difference of third columns times p_k's z.
    steps = rotations[:, 2, :3] - rotations[:, 2, 1:]
    steps *= (JOINT_Z * parameters.width)[:, None]  # the joint points' z, as ``joint_points`` computes them
    translations = np.zeros((3, 4, count))
    for k in range(3):
        np.add(translations[:, k], steps[:, k], out=translations[:, k + 1])
    return rotations.reshape((3, 3, 4) + batch), translations.reshape((3, 4) + batch)


# Where the entries computed above go in the (9 entries, 4 parts) rotations: flat entry 3 i + j and part.
_IDENTITY_ENTRIES = [0, 4, 8]
# Rows of ``entries``: c1, c2, s1, -s1, -s2, c1 s2, c1 c2, s1 s2, s1 c2 (c_k = cos phi_k, s_k = sin phi_k).
_PART_1_2_ENTRIES = (
    np.array([4, 5, 7, 8, 0, 1, 3, 4, 5, 6, 7, 8]),
    np.array([1, 1, 1, 1, 2, 2, 2, 2, 2, 2, 2, 2]),
)
_PART_1_2_VALUES = np.array([0, 3, 2, 0, 1, 4, 5, 6, 3, 7, 8, 0])


@dataclass(frozen=True)
class Connection:
    """Connector ``connector_a`` of module ``module_a`` mated to ``connector_b`` of ``module_b`` at ``angle_deg``."""

    module_a: int
    connector_a: int
    module_b: int
    connector_b: int
    angle_deg: int = 0


@dataclass
class ModelLayout:
    """Where each module of one or more trees sits in a legkit ``Model``.

    ``part_bodies[n, j]`` is the body index of part j (0 A, 1 link 1, 2 link 2, 3 B) of module n;
    ``joint_bodies[n, k]`` the body whose joint is module n's joint k, ``joint_q[n, k]`` its index in q (the
    model's q equals the module angles phi: reversed modules use negated axes); ``module_offset[n]`` is the
    module origin in part A's body frame (the module frame is A's body frame translated by it);
    ``tree_of_module[n]`` the tree (0-based) each module belongs to, ``origins[t]`` tree t's root position.
    """

    part_bodies: np.ndarray
    joint_bodies: np.ndarray
    joint_q: np.ndarray
    module_offset: np.ndarray
    tree_of_module: np.ndarray
    root_modules: np.ndarray
    origins: np.ndarray

    def module_poses(self, model: lk.Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World (rotations (..., N, 3, 3), translations (..., N, 3)) of every module frame at configuration q."""
        poses = lk.forward_kinematics(model, q)[..., self.part_bodies[:, 0], :, :]
        rotations = poses[..., :3, :3]
        translations = poses[..., :3, 3] + np.einsum("...ij,...j->...i", rotations, self.module_offset)
        return rotations, translations

    def module_angles(self, q: np.ndarray) -> np.ndarray:
        """Module joint angles phi (..., N, 3) from the model's q (..., nq)."""
        return np.asarray(q, dtype=float)[..., self.joint_q]


@dataclass
class ModuleTree:
    """Modules (numbered 0..n_modules-1, module 0 the root) and the connections between them.

    The root stands vertically on the ground on its ``A_end`` connector, which therefore must stay free.
    Construction validates: indices in range, connectors in 0..5, angles in {0, 90, 180, 270}, no connector
    used twice, no module connected to itself, and a tree (connected, no loops). Raises ValueError naming
    the offending argument.
    """

    n_modules: int
    connections: list[Connection] = field(default_factory=list)
    parameters: ModuleParameters = field(default_factory=ModuleParameters)

    def __post_init__(self) -> None:
        if integer(self.n_modules, "n_modules") < 1:
            raise ValueError(f"n_modules: must be >= 1, got {self.n_modules}")
        if not isinstance(self.parameters, ModuleParameters):
            raise TypeError(f"parameters: must be ModuleParameters, got {type(self.parameters).__name__}")
        self.n_modules = int(self.n_modules)
        self.connections = [c if isinstance(c, Connection) else Connection(*c) for c in self.connections]
        used: dict[tuple[int, int], int] = {}
        for index, c in enumerate(self.connections):
            for module, connector in ((c.module_a, c.connector_a), (c.module_b, c.connector_b)):
                if not 0 <= module < self.n_modules:
                    raise ValueError(f"connections[{index}]: module {module} out of range 0..{self.n_modules - 1}")
                if not 0 <= connector < 6:
                    raise ValueError(f"connections[{index}]: connector {connector} out of range 0..5")
                if (module, connector) in used:
                    raise ValueError(
                        f"connections[{index}]: connector {CONNECTOR_NAMES[connector]} of module {module} "
                        f"is already used by connections[{used[module, connector]}]"
                    )
                used[module, connector] = index
            if c.module_a == c.module_b:
                raise ValueError(f"connections[{index}]: module {c.module_a} is connected to itself")
            if c.angle_deg not in ANGLES_DEG:
                raise ValueError(f"connections[{index}]: angle_deg must be one of {ANGLES_DEG}, got {c.angle_deg!r}")
        if (0, 0) in used:
            raise ValueError(f"connections[{used[0, 0]}]: the root's A_end connector stands on the ground and must stay free")
        if len(self.connections) != self.n_modules - 1:
            raise ValueError(
                f"connections: a tree of {self.n_modules} modules has {self.n_modules - 1} connections, got {len(self.connections)}"
            )
        order, _, _ = self._breadth_first()
        if len(order) != self.n_modules:
            missing = sorted(set(range(self.n_modules)) - set(order))
            raise ValueError(f"connections: not a tree; modules {missing[:10]} are not connected to the root (there is a loop)")

    def neighbours(self) -> list[list[tuple[int, int, int, int]]]:
        """Per module, its (own connector, other module, other connector, angle_deg) links."""
        links: list[list[tuple[int, int, int, int]]] = [[] for _ in range(self.n_modules)]
        for c in self.connections:
            links[c.module_a].append((c.connector_a, c.module_b, c.connector_b, c.angle_deg))
            links[c.module_b].append((c.connector_b, c.module_a, c.connector_a, c.angle_deg))
        return links

    def _breadth_first(self) -> tuple[list[int], dict[int, tuple[int, int, int, int]], list[int]]:
        """(order, entry[module] = (parent, parent connector, own connector, angle), depth)."""
        links = self.neighbours()
        order, entry, depth = [0], {}, [0] * self.n_modules
        seen = {0}
        queue = deque([0])
        while queue:
            u = queue.popleft()
            for own, v, other, angle in links[u]:
                if v not in seen:
                    seen.add(v)
                    entry[v] = (u, own, other, angle)
                    depth[v] = depth[u] + 1
                    order.append(v)
                    queue.append(v)
        return order, entry, depth

    def connector_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(partner_module (N, 6), partner_connector (N, 6), mate_rotation (N, 6, 3, 3)); -1 / identity where free."""
        partner = np.full((self.n_modules, 6), -1, dtype=np.int64)
        partner_connector = np.full((self.n_modules, 6), -1, dtype=np.int64)
        mate = np.broadcast_to(np.eye(3), (self.n_modules, 6, 3, 3)).copy()
        for c in self.connections:
            rotation = mate_rotation(c.angle_deg)
            partner[c.module_a, c.connector_a], partner_connector[c.module_a, c.connector_a] = c.module_b, c.connector_b
            partner[c.module_b, c.connector_b], partner_connector[c.module_b, c.connector_b] = c.module_a, c.connector_a
            mate[c.module_a, c.connector_a] = rotation
            mate[c.module_b, c.connector_b] = rotation
        return partner, partner_connector, mate

    def diameter(self) -> int:
        """Number of connections on the longest path between two modules."""
        links = self.neighbours()

        def farthest(start: int) -> tuple[int, int]:
            distance = {start: 0}
            queue = deque([start])
            while queue:
                u = queue.popleft()
                for _, v, _, _ in links[u]:
                    if v not in distance:
                        distance[v] = distance[u] + 1
                        queue.append(v)
            far = max(distance, key=distance.__getitem__)
            return far, distance[far]

        return farthest(farthest(0)[0])[1]

    def to_model(self, gravity: Sequence[float] | None = None) -> tuple[lk.Model, ModelLayout]:
        """A fixed-base legkit ``Model`` with the root module standing vertically at the world origin.

        Body 0 is a massless ground anchor; the root's block A is fixed to it with its A_end face on z = 0.
        Returns the model and its ``ModelLayout``."""
        return build_model([self], origins=np.zeros((1, 2)), gravity=gravity)

    def lattice_cells(self) -> np.ndarray:
        """Integer lattice cells (2 N, 3) occupied by the blocks A and B of each module at zero joint angles,
        in module widths, with the root standing at the origin (its block A is the cell (0, 0, 0))."""
        order, entry, _ = self._breadth_first()
        rotation_c, position_c = self.parameters.connector_frames()
        w = self.parameters.width
        rotations = np.zeros((self.n_modules, 3, 3))
        translations = np.zeros((self.n_modules, 3))
        rotations[0] = np.eye(3)
        translations[0] = [0.0, 0.0, 0.0]
        for v in order[1:]:
            u, own_u, own_v, angle = entry[v]
            rotations[v], translations[v] = _child_module_pose(rotations[u], translations[u], rotation_c, position_c, own_u, own_v, angle)
        centres = np.concatenate([translations + rotations @ [0, 0, 0.5 * w], translations + rotations @ [0, 0, 1.5 * w]])
        return np.rint(centres / w - [0.0, 0.0, 0.5]).astype(np.int64)


def _child_module_pose(
    rotation_u: np.ndarray, translation_u: np.ndarray, rotation_c: np.ndarray, position_c: np.ndarray, own_u: int, own_v: int,
    angle: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Module v's frame in the frame where module u's frame is (rotation_u, translation_u), at zero angles."""
    connector_rotation = rotation_u @ rotation_c[own_u]
    connector_position = translation_u + rotation_u @ position_c[own_u]
    rotation_v_connector = connector_rotation @ mate_rotation(angle)
    rotation = rotation_v_connector @ rotation_c[own_v].T
    return rotation, connector_position - rotation @ position_c[own_v]


def build_model(trees: Sequence[ModuleTree], origins: np.ndarray, gravity: Sequence[float] | None = None) -> tuple[lk.Model, ModelLayout]:
    """One fixed-base legkit ``Model`` holding several module trees side by side (no connection between them).

    ``origins`` (T, 2) are the (x, y) ground positions (m) of the trees' roots, which stand vertically with
    their A_end face on z = 0. Body 0 is a massless ground anchor. Modules are numbered tree after tree in
    each tree's own numbering; bodies are added breadth first from each root (parents before children). The
    module angles phi equal the model's q of the corresponding joints."""
    origins = float_array(origins, "origins", shape=(len(trees), 2))
    model = lk.Model(floating_base=False, gravity=gravity)
    total = sum(t.n_modules for t in trees)
    part_bodies = np.zeros((total, 4), dtype=np.int64)
    joint_bodies = np.zeros((total, 3), dtype=np.int64)
    module_offset = np.zeros((total, 3))
    tree_of_module = np.zeros(total, dtype=np.int64)
    reversed_module = np.zeros(total, dtype=bool)
    roots = []
    first = 0
    for tree_index, tree in enumerate(trees):
        parameters = tree.parameters
        parts = parameters.part_mass_properties()
        points = parameters.joint_points
        rotation_c, position_c = parameters.connector_frames()
        order, entry, _ = tree._breadth_first()
        for n in order:
            g = first + n
            tree_of_module[g] = tree_index
            if n == 0:
                roots.append(g)
                attach, placement_rotation, placement_translation, reverse = 0, np.eye(3), np.array([*origins[tree_index], 0.0]), False
            else:
                u, own_u, own_v, angle = entry[n]
                reverse = CONNECTOR_BLOCK[own_v] == 1
                u_part = 3 if CONNECTOR_BLOCK[own_u] == 1 else 0
                attach = int(part_bodies[first + u, u_part])
                # Connector frames in the part frames: each part frame is the zero-angle module frame shifted
                # to the part's origin, so only the positions change.
                connector_u_rot = rotation_c[own_u]
                connector_u_pos = position_c[own_u] - _part_origin(points, u_part, bool(reversed_module[first + u]))
                connector_v_rot = rotation_c[own_v]
                connector_v_pos = position_c[own_v] - _part_origin(points, 3 if reverse else 0, reverse)
                placement_rotation = connector_u_rot @ mate_rotation(angle) @ connector_v_rot.T
                placement_translation = connector_u_pos - placement_rotation @ connector_v_pos
            # Chain order and frame origins of the parts: entering via A, parts 0..3 with origins 0, p1, p2, p3;
            # entering via B, parts 3..0 with origins p3, p3, p2, p1 (each body frame sits on its parent joint).
            chain, axis_sign = ([3, 2, 1, 0], -1.0) if reverse else ([0, 1, 2, 3], 1.0)
            origins_part = [_part_origin(points, part, reverse) for part in chain]
            part_body: dict[int, int] = {}
            for step, part in enumerate(chain):
                body = parts[part].transformed(np.eye(3), -origins_part[step])
                name = f"t{tree_index}m{n}p{part}"
                if step == 0:
                    index = model.add_fixed(attach, (placement_rotation, placement_translation), body, name=name)
                else:
                    joint = min(part, chain[step - 1])  # joint k (0-based) sits between parts k and k + 1
                    translation = origins_part[step] - origins_part[step - 1]
                    index = model.add_revolute(part_body[chain[step - 1]], axis_sign * JOINT_AXES[joint], (np.eye(3), translation), body, name=name)
                    joint_bodies[g, joint] = index
                part_body[part] = index
            part_bodies[g] = [part_body[p] for p in range(4)]
            reversed_module[g] = reverse
            module_offset[g] = -_part_origin(points, 0, reverse)
        first += tree.n_modules
    # Each joint's servo, from its tree's parameters.
    armature, damping = np.zeros(model.nv), np.zeros(model.nv)
    for tree, bodies in zip(trees, np.split(joint_bodies, np.cumsum([t.n_modules for t in trees])[:-1])):
        columns = np.array(model.idx_v)[bodies]
        armature[columns], damping[columns] = tree.parameters.servo_armature, tree.parameters.servo_damping
    model.armature, model.damping = armature, damping
    joint_q = np.array(model.idx_q)[joint_bodies]
    layout = ModelLayout(part_bodies, joint_bodies, joint_q, module_offset, tree_of_module, np.array(roots), origins)
    return model, layout


def _part_origin(points: np.ndarray, part: int, reversed_module: bool) -> np.ndarray:
    """Origin of a part's body frame in zero-angle module coordinates: each body frame sits on the joint that
    attaches it to its parent body (block A at the module origin when the module is entered through A)."""
    if reversed_module:
        return np.array([points[0], points[1], points[2], points[2]][part])
    return np.array([np.zeros(3), points[0], points[1], points[2]][part])


def random_tree(
    n_modules: int = 20, branches: int = 4, seed: int = 0, parameters: ModuleParameters | None = None
) -> ModuleTree:
    """A random tree like the seed experiment's: a vertical root plus ``n_modules`` modules in ``branches``
    branches of (as equal as possible) sizes, each branch hanging off its own free connector of the root.

    The returned tree has ``n_modules + 1`` modules (the root is module 0). Within a branch each new module
    attaches one of its six connectors, at a random angle in {0, 90, 180, 270}, to a random free connector
    of a random module already in the branch. Placements whose blocks would overlap another block, or go
    below the ground, at zero joint angles are rejected (blocks sit on a lattice of module widths), so the
    zero configuration is physically valid. Deterministic for a given seed. ``branches`` must be 1..5 (the
    root has five free connectors); ``n_modules`` at most MAX_RANDOM_MODULES."""
    for name, value in (("n_modules", n_modules), ("branches", branches), ("seed", seed)):
        integer(value, name)
    if n_modules < 0 or seed < 0:
        name, value = ("n_modules", n_modules) if n_modules < 0 else ("seed", seed)
        raise ValueError(f"{name}: must be >= 0, got {value}")
    if n_modules > MAX_RANDOM_MODULES:
        raise ValueError(f"n_modules: must be <= {MAX_RANDOM_MODULES} (larger random trees box themselves in), got {n_modules}")
    if not 1 <= branches <= 5:
        raise ValueError(f"branches: must be in 1..5 (the root has five free connectors), got {branches}")
    if branches > max(n_modules, 1):
        raise ValueError(f"branches: must be <= n_modules ({n_modules}), got {branches}")
    parameters = ModuleParameters() if parameters is None else parameters
    instance(parameters, ModuleParameters, "parameters")
    rng = np.random.default_rng(seed)
    rotation_c, position_c = parameters.connector_frames()
    w = parameters.width
    unit_rotation_c = rotation_c
    unit_position_c = position_c / w
    sizes = [n_modules // branches + (1 if b < n_modules % branches else 0) for b in range(branches)]
    # A child's pose in its parent's frame, per (parent connector, child connector, angle), in module widths.
    relative = {
        (a, b, angle): _child_module_pose(np.eye(3), np.zeros(3), unit_rotation_c, unit_position_c, a, b, angle)
        for a in range(6) for b in range(6) for angle in ANGLES_DEG
    }

    def grow() -> list[Connection] | None:
        # Poses in module widths at zero angles; the root stands at the origin.
        rotations = [np.eye(3)]
        translations = [np.zeros(3)]
        occupied: set[tuple[int, ...]] = {(0, 0, 0), (0, 0, 1)}
        free = {0: [1, 2, 3, 4, 5]}
        connections: list[Connection] = []

        def cells(rotation: np.ndarray, translation: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
            a = np.rint(translation + rotation @ [0, 0, 0.5] - [0, 0, 0.5]).astype(int)
            b = np.rint(translation + rotation @ [0, 0, 1.5] - [0, 0, 0.5]).astype(int)
            return tuple(a), tuple(b)

        def place(u: int, own_u: int) -> bool:
            for own_v, angle in zip(rng.permutation(6), rng.choice(ANGLES_DEG, size=6)):
                relative_rotation, relative_translation = relative[own_u, own_v, angle]
                rotation = rotations[u] @ relative_rotation
                translation = translations[u] + rotations[u] @ relative_translation
                cell_a, cell_b = cells(rotation, translation)
                if cell_a in occupied or cell_b in occupied or min(cell_a[2], cell_b[2]) < 0:
                    continue
                v = len(rotations)
                rotations.append(rotation)
                translations.append(translation)
                occupied.update((cell_a, cell_b))
                free[u].remove(own_u)
                free[v] = [c for c in range(6) if c != own_v]
                connections.append(Connection(u, int(own_u), v, int(own_v), int(angle)))
                return True
            return False

        def try_attach(members: list[int]) -> bool:
            # Sample a few (module, free connector) pairs first, which is cheap in big trees; only when they all
            # fail, try every pair in random order.
            for u in (members[i] for i in rng.integers(len(members), size=8)):
                if free[u] and place(u, free[u][rng.integers(len(free[u]))]):
                    return True
            pairs = [(u, c) for u in members for c in free[u]]
            return any(place(*pairs[i]) for i in rng.permutation(len(pairs)))

        for size in sizes:
            branch: list[int] = []
            for i in range(size):
                if not try_attach(branch if i else [0]):
                    return None  # boxed in: start the tree again
                branch.append(len(rotations) - 1)
        return connections

    for _ in range(100):
        connections = grow()
        if connections is not None:
            return ModuleTree(n_modules + 1, connections, parameters)
    raise ValueError(f"n_modules: could not place {n_modules} modules without overlap in 100 attempts (seed {seed})")
