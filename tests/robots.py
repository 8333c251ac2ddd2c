"""Random legkit models and their exact Pinocchio twins, for the differential dynamics tests.

A `Twin` holds one random kinematic tree built twice, from the same numbers: once as a `legkit.Model`
and once as a `pinocchio.Model`. The mapping is:

* legkit floating base -> `JointModelFreeFlyer` as pin joint 1 carrying the base inertia; a fixed base
  -> pin's universe (joint 0), whose inertia pin ignores (legkit: "its mass is irrelevant").
* every revolute / prismatic body -> one pin joint (RX/RY/RZ, PX/PY/PZ when the axis is exactly +x/+y/+z,
  otherwise the *Unaligned joint with the normalised axis); every helical body -> JointModelHelicalUnaligned
  with the normalised axis and the same pitch; every spherical body (trees built with `ball=True`) ->
  JointModelSpherical (q a unit quaternion [x, y, z, w] in both, v the angular velocity in the body frame).
  Pinocchio's CRBA and Minverse assume that every
  joint's subtree occupies a contiguous range of v (depth-first joint order), while legkit accepts any
  parent-before-child numbering; so pin joints are added in depth-first pre-order of the legkit tree and
  the twin records the permutation (`perm_q`, `perm_v`, and the converters q_pin / v_pin / v_lk / m_lk /
  cols_lk). When the legkit bodies are themselves numbered depth-first (`depth_first=True`) the
  permutation is the identity and the q/v vectors are literally identical.
* half the trees carry a random armature on their joints, set on both models (pin's in its v order).
* every fixed body -> no pin joint: its inertia is appended (`appendBodyToJoint`) to the pin joint of its
  nearest movable ancestor, with the composed placement, and `body_joint[i]`, `body_in_joint[i]` record
  which pin joint carries legkit body i and where the body frame sits in that joint frame.

Models are generated from a seeded numpy Generator (hypothesis draws the seed and the size), so large
trees cost one draw and hypothesis still shrinks towards small trees and seed 0. `Twin.describe()`
prints Python source that rebuilds the legkit model exactly, for reproducers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from hypothesis import event
from hypothesis import strategies as st

import legkit as lk

UNIT_AXES = np.eye(3)
REVOLUTE = [pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ]
PRISMATIC = [pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ]


# --------------------------------------------------------------------------------------------------
# Random ingredients
# --------------------------------------------------------------------------------------------------


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Proper rotation from a random unit quaternion (w, x, y, z), orthonormal to ~1e-16."""
    w, x, y, z = _unit_quaternion(rng)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _unit_quaternion(rng: np.random.Generator) -> np.ndarray:
    while True:
        q = rng.normal(size=4)
        n = np.linalg.norm(q)
        if n > 1e-3:
            return q / n


def random_axis(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(axis given to legkit, its unit direction given to pin).

    About a third are exactly +-x/y/z; legkit sometimes receives a non-unit multiple (it normalises).
    """
    if rng.random() < 0.35:
        unit = UNIT_AXES[rng.integers(3)] * (1.0 if rng.random() < 0.7 else -1.0)
    else:
        while True:
            d = rng.normal(size=3)
            if np.linalg.norm(d) > 0.1:
                break
        unit = d / np.linalg.norm(d)
    scale = 1.0 if rng.random() < 0.6 else float(rng.uniform(0.2, 5.0))
    return unit * scale, unit


def random_placement(rng: np.random.Generator) -> np.ndarray:
    """4x4 homogeneous transform: random rotation (sometimes identity), translation up to 0.5 m."""
    T = np.eye(4)
    if rng.random() < 0.85:
        T[:3, :3] = random_rotation(rng)
    T[:3, 3] = rng.uniform(-0.5, 0.5, size=3) * (1.0 if rng.random() < 0.9 else 0.0)
    return T


def random_body(rng: np.random.Generator) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, com, inertia about com): a rotated solid box, mass 0.1-5 kg, edges 0.02-0.5 m, com offset."""
    mass = float(rng.uniform(0.1, 5.0))
    a, b, c = rng.uniform(0.02, 0.5, size=3)
    principal = mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    R = random_rotation(rng)
    inertia = R @ np.diag(principal) @ R.T
    inertia = 0.5 * (inertia + inertia.T)
    com = rng.uniform(-0.3, 0.3, size=3)
    return mass, com, inertia


# --------------------------------------------------------------------------------------------------
# The twin
# --------------------------------------------------------------------------------------------------


@dataclass(repr=False)
class Twin:
    model: lk.Model
    pin_model: pin.Model
    floating: bool
    parents: list[int]
    kinds: list[str]  # "base", "revolute", "prismatic", "helical", "spherical", "fixed"
    axes: list[np.ndarray | None]  # as given to legkit (possibly non-unit)
    placements: list[np.ndarray]  # 4x4 joint placement in the parent body frame (identity for the base)
    bodies: list[tuple[float, np.ndarray, np.ndarray] | None]  # (mass, com, inertia) or None (massless)
    body_joint: list[int]  # pin joint carrying legkit body i
    body_in_joint: list[pin.SE3]  # placement of legkit body i's frame in that pin joint's frame
    gravity: np.ndarray
    placement_as_tuple: list[bool]
    perm_q: np.ndarray  # pin q = legkit q[perm_q]
    perm_v: np.ndarray  # pin v = legkit v[perm_v]
    depth_first: bool
    lk_iv: list[int]  # legkit velocity index of each movable body (0 for the base / fixed bodies)
    pitches: list[float]  # m/rad, of the helical joints (0 for the other bodies)
    lk_iq: list[int] = field(default_factory=list)  # legkit configuration index of each movable body (0 for the others)

    def __repr__(self) -> str:  # short: the full model is in describe(), noted by the tests on failure
        kinds = "".join({"base": "B", "revolute": "R", "prismatic": "P", "helical": "H", "spherical": "S", "fixed": "F"}[k] for k in self.kinds)
        return f"Twin(nbodies={self.nbodies}, floating={self.floating}, depth_first={self.depth_first}, kinds={kinds})"

    @property
    def quaternions(self) -> list[int]:
        """The legkit q index of each spherical joint's quaternion."""
        return [self.lk_iq[i] for i, kind in enumerate(self.kinds) if kind == "spherical"]

    @property
    def rotations(self) -> list[int]:
        """The legkit v index of each angular velocity that turns a quaternion: the base's and the spherical joints'."""
        return ([3] if self.floating else []) + [self.lk_iv[i] for i, kind in enumerate(self.kinds) if kind == "spherical"]

    # ---- sizes -------------------------------------------------------------------------------------
    @property
    def nbodies(self) -> int:
        return len(self.parents)

    @property
    def nq(self) -> int:
        return self.pin_model.nq

    @property
    def nv(self) -> int:
        return self.pin_model.nv

    def data(self) -> pin.Data:
        return self.pin_model.createData()

    # ---- random states -----------------------------------------------------------------------------
    def random_q(self, rng: np.random.Generator) -> np.ndarray:
        """Joint coordinates uniform in [-pi, pi]; the quaternions normalised normal 4-vectors."""
        q = rng.uniform(-np.pi, np.pi, size=self.nq)
        for k in ([3] if self.floating else []) + self.quaternions:
            q[k : k + 4] = _unit_quaternion(rng)  # any unit 4-vector; layout [qx, qy, qz, qw]
        return q

    def random_v(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(-3.0, 3.0, size=self.nv)

    def random_f_ext(self, rng: np.random.Generator) -> np.ndarray:
        """Per-body external wrenches [f, n] in each body's frame; some bodies get none."""
        f = rng.uniform(-20.0, 20.0, size=(self.nbodies, 6))
        f[rng.random(self.nbodies) < 0.2] = 0.0
        return f

    # ---- layout conversions (legkit body order <-> pin depth-first joint order) ----------------------
    def q_pin(self, q) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(q, float)[..., self.perm_q])

    def v_pin(self, v) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(v, float)[..., self.perm_v])

    def v_lk(self, v_pin) -> np.ndarray:
        """A pin joint-space vector (last axis) in legkit order."""
        v_pin = np.asarray(v_pin, float)
        out = np.empty_like(v_pin)
        out[..., self.perm_v] = v_pin
        return out

    def m_lk(self, m_pin) -> np.ndarray:
        """A pin nv x nv matrix in legkit order."""
        m_pin = np.asarray(m_pin, float)
        out = np.empty_like(m_pin)
        out[np.ix_(self.perm_v, self.perm_v)] = m_pin
        return out

    def cols_lk(self, j_pin) -> np.ndarray:
        """A pin (k, nv) matrix (e.g. a Jacobian) with its columns in legkit order."""
        j_pin = np.asarray(j_pin, float)
        if j_pin.ndim == 1:  # eigenpy hands back a (6, 1) matrix as a vector
            j_pin = j_pin.reshape(-1, self.nv) if self.nv else np.zeros((j_pin.size, 0))
        out = np.empty_like(j_pin)
        out[:, self.perm_v] = j_pin
        return out

    # ---- pin-side mappings ---------------------------------------------------------------------------
    def pin_fext(self, f_ext: np.ndarray) -> pin.StdVec_Force:
        """legkit per-body wrenches (body frames) -> pin per-joint wrenches (LOCAL joint frames), summed."""
        total = [pin.Force.Zero() for _ in range(self.pin_model.njoints)]
        for i in range(self.nbodies):
            f = pin.Force(np.asarray(f_ext[i, :3], float), np.asarray(f_ext[i, 3:], float))
            j = self.body_joint[i]
            total[j] = total[j] + self.body_in_joint[i].act(f)
        out = pin.StdVec_Force()
        for f in total:
            out.append(f)
        return out

    def pin_world_poses(self, data: pin.Data) -> np.ndarray:
        """World pose of every legkit body frame from pin's data.oMi (after forwardKinematics)."""
        poses = [data.oMi[self.body_joint[i]] * self.body_in_joint[i] for i in range(self.nbodies)]
        return np.array([p.homogeneous for p in poses])

    def add_pin_frame(self, body: int, point: np.ndarray | None) -> int:
        """Add a pin operational frame at `point` (body frame) on legkit body `body`; return its id."""
        offset = pin.SE3(np.eye(3), np.zeros(3) if point is None else np.asarray(point, float))
        placement = self.body_in_joint[body] * offset
        name = f"probe_{self.pin_model.nframes}"
        return self.pin_model.addFrame(pin.Frame(name, self.body_joint[body], placement, pin.FrameType.OP_FRAME))

    # ---- reproducers -------------------------------------------------------------------------------
    def describe(self) -> str:
        """Python source rebuilding the legkit model exactly (floats by repr)."""

        def arr(a) -> str:
            return "np.array(" + repr(np.asarray(a).tolist()) + ")"

        def mp(b) -> str:
            if b is None:
                return "None"
            return f"lk.MassProperties({b[0]!r}, {arr(b[1])}, {arr(b[2])})"

        lines = [
            f"model = lk.Model(floating_base={self.floating}, base={mp(self.bodies[0])}, gravity={arr(self.gravity)})"
        ]
        for i in range(1, self.nbodies):
            pl = arr(self.placements[i])
            if self.kinds[i] in ("fixed", "spherical"):
                lines.append(f"model.add_{self.kinds[i]}({self.parents[i]}, {pl}, {mp(self.bodies[i])}, 'b{i}')")
            else:
                axis, body = arr(self.axes[i]), mp(self.bodies[i])
                pitch = f"{self.pitches[i]!r}, " if self.kinds[i] == "helical" else ""
                lines.append(f"model.add_{self.kinds[i]}({self.parents[i]}, {axis}, {pitch}{pl}, {body}, 'b{i}')")
        return "\n".join(lines)


def build_twin(
    rng: np.random.Generator,
    n_bodies: int,
    floating: bool,
    *,
    anchored_mass: bool = True,
    gravity: np.ndarray | None = None,
    massive_fixed_base: bool | None = None,
    depth_first: bool | None = None,
    ball: bool = False,
) -> Twin:
    """A random tree of `n_bodies` bodies (base included) and its pin twin.

    anchored_mass=False: with a fixed base, the base and every body welded to it through fixed joints
    are massless, so quantities like the centre of mass do not depend on whether those (immobile)
    bodies count; pin never counts them.
    depth_first=True numbers the legkit bodies in depth-first pre-order (then the q/v layouts of legkit and
    pin coincide); otherwise parents are any earlier body and pin (whose CRBA / Minverse need depth-first
    joint order) gets its joints in depth-first order with the permutation recorded in the twin.
    ball=True makes about a fifth of the joints spherical; without it the trees are those drawn before ball joints
    existed (the same seeds, the same trees).
    """
    if n_bodies < 1:
        raise ValueError("n_bodies must be >= 1")
    if depth_first is None:
        depth_first = bool(rng.random() < 0.3)
    g = np.asarray(lk.Model().gravity) if gravity is None else np.asarray(gravity, float)

    # ---- the random tree, in legkit body order ----------------------------------------------------
    if floating:
        base = random_body(rng)
    elif not anchored_mass:
        base = None
    else:
        if massive_fixed_base is None:
            massive_fixed_base = bool(rng.random() < 0.5)
        base = random_body(rng) if massive_fixed_base else None
    parents, kinds, axes, units, pitches = [0], ["base"], [None], [None], [0.0]  # the base is its own parent, as in lk and pin
    placements, bodies, as_tuple = [np.eye(4)], [base], [False]
    anchored = [not floating]  # welded to the (fixed) world
    path = [0]  # the current root-to-last-body path (for depth-first numbering)
    for i in range(1, n_bodies):
        if depth_first:
            # a body on the current root-to-leaf path (mostly near its end): keeps the numbering depth-first
            lo = max(0, len(path) - 3) if rng.random() < 0.7 else 0
            parent = path[int(rng.integers(lo, len(path)))]
            path = path[: path.index(parent) + 1] + [i]
        elif rng.random() < 0.6:  # mostly a recent body (deep chains), sometimes any earlier one (branching)
            parent = int(rng.integers(max(0, i - 3), i))
        else:
            parent = int(rng.integers(0, i))
        u = rng.random()
        kind = "revolute" if u < 0.6 else "prismatic" if u < 0.75 else "helical" if u < 0.9 else "fixed"
        body = random_body(rng)
        if ball and rng.random() < 0.2:
            kind = "spherical"
        if kind == "fixed" and (rng.random() < 0.3 or (anchored[parent] and not anchored_mass)):
            body = None  # a massless marker frame
        if kind in ("fixed", "spherical"):
            axis = unit = None
        else:
            axis, unit = random_axis(rng)
        parents.append(parent)
        kinds.append(kind)
        pitches.append(float(rng.uniform(-0.2, 0.2)) if kind == "helical" else 0.0)
        axes.append(axis)
        units.append(unit)
        placements.append(random_placement(rng))
        bodies.append(body)
        as_tuple.append(bool(rng.random() < 0.5))
        anchored.append(kind == "fixed" and anchored[parent])

    # ---- legkit, in body order -----------------------------------------------------------------------
    def mp(b):
        return None if b is None else lk.MassProperties(*b)

    model = lk.Model(floating_base=floating, base=mp(base), base_name="base", gravity=None if gravity is None else g)
    lk_iv = [0] * n_bodies  # legkit velocity index of each movable body (body order; free flyer first)
    lk_iq = [0] * n_bodies  # and its configuration index
    nv, nq = (6, 7) if floating else (0, 0)
    for i in range(1, n_bodies):
        T = placements[i]
        placement = (T[:3, :3].copy(), T[:3, 3].copy()) if as_tuple[i] else T.copy()
        if kinds[i] == "fixed":
            idx = model.add_fixed(parents[i], placement, mp(bodies[i]), f"b{i}")
        elif kinds[i] == "spherical":
            idx = model.add_spherical(parents[i], placement, mp(bodies[i]), f"b{i}")
            lk_iv[i], lk_iq[i] = nv, nq
            nv, nq = nv + 3, nq + 4
        else:
            if kinds[i] == "helical":
                idx = model.add_helical(parents[i], axes[i], pitches[i], placement, mp(bodies[i]), f"b{i}")
            else:
                add = model.add_revolute if kinds[i] == "revolute" else model.add_prismatic
                idx = add(parents[i], axes[i], placement, mp(bodies[i]), f"b{i}")
            lk_iv[i], lk_iq[i] = nv, nq
            nv, nq = nv + 1, nq + 1
        assert idx == i, (idx, i)

    # ---- pin, in depth-first pre-order ------------------------------------------------------------------
    children: list[list[int]] = [[] for _ in range(n_bodies)]
    for i in range(1, n_bodies):
        children[parents[i]].append(i)
    order, stack = [], [0]
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(children[i]))

    pin_model = pin.Model()
    pin_model.gravity = pin.Motion(g, np.zeros(3))
    body_joint = [0] * n_bodies
    body_in_joint = [pin.SE3.Identity()] * n_bodies
    perm_q = list(range(7)) if floating else []
    perm_v = list(range(6)) if floating else []
    for i in order:
        if i == 0:
            if floating:
                j = pin_model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
                pin_model.appendBodyToJoint(j, pin.Inertia(base[0], base[1], base[2]), pin.SE3.Identity())
                body_joint[0] = j
            continue
        T = placements[i]
        X = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
        pj, pX = body_joint[parents[i]], body_in_joint[parents[i]]
        body = bodies[i]
        if kinds[i] == "fixed":
            body_joint[i] = pj
            body_in_joint[i] = pX * X
            if body is not None:
                pin_model.appendBodyToJoint(pj, pin.Inertia(body[0], body[1], body[2]), pX * X)
            continue
        unit = units[i]
        aligned = [k for k in range(3) if np.array_equal(unit, UNIT_AXES[k])]
        if kinds[i] == "spherical":
            jm = pin.JointModelSpherical()
        elif kinds[i] == "helical":
            jm = pin.JointModelHelicalUnaligned(unit, pitches[i])
        elif kinds[i] == "revolute":
            jm = REVOLUTE[aligned[0]]() if aligned else pin.JointModelRevoluteUnaligned(unit)
        else:
            jm = PRISMATIC[aligned[0]]() if aligned else pin.JointModelPrismaticUnaligned(unit)
        j = pin_model.addJoint(pj, jm, pX * X, f"b{i}")
        pin_model.appendBodyToJoint(j, pin.Inertia(body[0], body[1], body[2]), pin.SE3.Identity())
        body_joint[i] = j
        width_v, width_q = (3, 4) if kinds[i] == "spherical" else (1, 1)
        perm_v.extend(range(lk_iv[i], lk_iv[i] + width_v))
        perm_q.extend(range(lk_iq[i], lk_iq[i] + width_q))

    # Half the trees carry armature on their joints (Pinocchio's model.armature, in its own v order).
    if rng.random() < 0.5:
        armature = np.where(np.arange(nv) < (6 if floating else 0), 0.0, rng.uniform(0.0, 0.3, nv))
        model.armature = armature
        pin_model.armature = armature[np.array(perm_v, dtype=int)]
    twin = Twin(
        model, pin_model, floating, parents, kinds, axes, placements, bodies, body_joint, body_in_joint, g, as_tuple,
        np.array(perm_q, dtype=int), np.array(perm_v, dtype=int), depth_first, lk_iv, pitches,
        lk_iq,
    )
    assert model.nq == pin_model.nq and model.nv == pin_model.nv == nv, (model.nq, pin_model.nq, model.nv, pin_model.nv)
    assert model.nbodies == n_bodies
    if depth_first:  # depth-first numbering: identical layouts
        assert np.array_equal(twin.perm_v, np.arange(nv)), twin.perm_v
    return twin


# --------------------------------------------------------------------------------------------------
# Hypothesis helpers
# --------------------------------------------------------------------------------------------------


def body_counts(max_bodies: int = 200):
    """Mostly small trees (1-8 bodies), sometimes medium (9-40), rarely large (41-max_bodies)."""

    @st.composite
    def counts(draw):
        size_class = draw(st.integers(0, 19))
        if size_class < 12 or max_bodies <= 8:
            return draw(st.integers(1, min(8, max_bodies)))
        if size_class < 17 or max_bodies <= 40:
            return draw(st.integers(9, min(40, max_bodies)))
        return draw(st.integers(41, max_bodies))

    return counts()


def random_model(draw, n_bodies: int, floating: bool, **kwargs) -> Twin:
    """Inside a @st.composite: draw a seed and build the twin (keyword arguments go to build_twin)."""
    seed = draw(st.integers(0, 2**32 - 1), label="model_seed")
    return build_twin(np.random.default_rng(seed), n_bodies, floating, **kwargs)


@st.composite
def twins(draw, max_bodies: int = 200, floating: bool | None = None, ball: bool | None = None, **kwargs) -> Twin:
    """A random twin: size from body_counts(max_bodies), fixed or floating base, with or without spherical joints
    (drawn unless given)."""
    n = draw(body_counts(max_bodies), label="n_bodies")
    fl = draw(st.booleans(), label="floating") if floating is None else floating
    kwargs["ball"] = draw(st.booleans(), label="ball") if ball is None else ball
    event("bodies", "1-8" if n <= 8 else ("9-40" if n <= 40 else "41+"))
    return random_model(draw, n, fl, **kwargs)


def rngs():
    """A seeded numpy Generator for random states (hypothesis shrinks the seed)."""
    return st.integers(0, 2**32 - 1).map(np.random.default_rng)
