"""Random legkit models and their exact Pinocchio twins, for the differential dynamics tests.

A `Twin` holds one random kinematic tree built twice, from the same numbers: once as a `legkit.Model`
and once as a `pinocchio.Model`. The mapping is:

* legkit floating base -> `JointModelFreeFlyer` as pin joint 1 carrying the base inertia; a fixed base
  -> pin's universe (joint 0), whose inertia pin ignores (legkit: "its mass is irrelevant").
* every revolute / prismatic body -> one pin joint (RX/RY/RZ, PX/PY/PZ when the axis is exactly +x/+y/+z,
  otherwise the *Unaligned joint with the normalised axis), added in legkit body order, so that q and v
  are laid out identically in both libraries.
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
from hypothesis import strategies as st

import legkit as lk

UNIT_AXES = np.eye(3)


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


@dataclass
class Twin:
    model: lk.Model
    pin_model: pin.Model
    floating: bool
    parents: list[int]
    kinds: list[str]  # "base", "revolute", "prismatic", "fixed"
    axes: list[np.ndarray | None]  # as given to legkit (possibly non-unit)
    placements: list[np.ndarray]  # 4x4 joint placement in the parent body frame (identity for the base)
    bodies: list[tuple[float, np.ndarray, np.ndarray] | None]  # (mass, com, inertia) or None (massless)
    body_joint: list[int]  # pin joint carrying legkit body i
    body_in_joint: list[pin.SE3]  # placement of legkit body i's frame in that pin joint's frame
    gravity: np.ndarray
    placement_as_tuple: list[bool] = field(default_factory=list)

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
        """Joint coordinates uniform in [-pi, pi]; the base quaternion a normalised normal 4-vector."""
        q = rng.uniform(-np.pi, np.pi, size=self.nq)
        if self.floating:
            x, y, z, w = _unit_quaternion(rng)  # any unit 4-vector; layout [qx, qy, qz, qw]
            q[3:7] = (x, y, z, w)
        return q

    def random_v(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(-3.0, 3.0, size=self.nv)

    def random_f_ext(self, rng: np.random.Generator) -> np.ndarray:
        """Per-body external wrenches [f, n] in each body's frame; some bodies get none."""
        f = rng.uniform(-20.0, 20.0, size=(self.nbodies, 6))
        f[rng.random(self.nbodies) < 0.2] = 0.0
        return f

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
        return np.array([(data.oMi[self.body_joint[i]] * self.body_in_joint[i]).homogeneous for i in range(self.nbodies)])

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
            if self.kinds[i] == "fixed":
                lines.append(f"model.add_fixed({self.parents[i]}, {pl}, {mp(self.bodies[i])}, 'b{i}')")
            else:
                lines.append(
                    f"model.add_{self.kinds[i]}({self.parents[i]}, {arr(self.axes[i])}, {pl}, {mp(self.bodies[i])}, 'b{i}')"
                )
        return "\n".join(lines)


def build_twin(
    rng: np.random.Generator,
    n_bodies: int,
    floating: bool,
    *,
    anchored_mass: bool = True,
    gravity: np.ndarray | None = None,
    massive_fixed_base: bool | None = None,
) -> Twin:
    """A random tree of `n_bodies` bodies (base included) and its pin twin.

    anchored_mass=False: with a fixed base, the base and every body welded to it through fixed joints
    are massless, so quantities like the centre of mass do not depend on whether those (immobile)
    bodies count; pin never counts them.
    """
    if n_bodies < 1:
        raise ValueError("n_bodies must be >= 1")
    g = np.array([0.0, 0.0, -9.81]) if gravity is None else np.asarray(gravity, float)
    pin_model = pin.Model()
    pin_model.gravity = pin.Motion(g, np.zeros(3))

    if floating:
        base = random_body(rng)
    elif not anchored_mass:
        base = None
    else:
        if massive_fixed_base is None:
            massive_fixed_base = bool(rng.random() < 0.5)
        base = random_body(rng) if massive_fixed_base else None
    base_mp = None if base is None else lk.MassProperties(*base)
    model = lk.Model(floating_base=floating, base=base_mp, base_name="base", gravity=None if gravity is None else g)

    parents, kinds, axes, placements, bodies = [-1], ["base"], [None], [np.eye(4)], [base]
    body_joint: list[int] = []
    body_in_joint: list[pin.SE3] = []
    as_tuple = [False]
    if floating:
        j = pin_model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
        pin_model.appendBodyToJoint(j, pin.Inertia(base[0], base[1], base[2]), pin.SE3.Identity())
        body_joint.append(j)
    else:
        body_joint.append(0)
    body_in_joint.append(pin.SE3.Identity())
    anchored = [not floating]  # welded to the (fixed) world

    for i in range(1, n_bodies):
        # Parent: mostly a recent body (deep chains), sometimes any earlier body (branching).
        if rng.random() < 0.6:
            parent = int(rng.integers(max(0, i - 3), i))
        else:
            parent = int(rng.integers(0, i))
        u = rng.random()
        kind = "revolute" if u < 0.7 else ("prismatic" if u < 0.9 else "fixed")
        T = random_placement(rng)
        X = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
        body = random_body(rng)
        if kind == "fixed" and rng.random() < 0.3:
            body = None  # a massless marker frame
        if kind == "fixed" and anchored[parent] and not anchored_mass:
            body = None
        use_tuple = bool(rng.random() < 0.5)
        placement = (T[:3, :3].copy(), T[:3, 3].copy()) if use_tuple else T.copy()
        body_mp = None if body is None else lk.MassProperties(*body)
        name = f"b{i}"
        pj, pX = body_joint[parent], body_in_joint[parent]
        if kind == "fixed":
            idx = model.add_fixed(parent, placement, body_mp, name)
            axis = None
            in_joint = pX * X
            if body is not None:
                pin_model.appendBodyToJoint(pj, pin.Inertia(body[0], body[1], body[2]), in_joint)
            body_joint.append(pj)
            body_in_joint.append(in_joint)
            anchored.append(anchored[parent])
        else:
            axis, unit = random_axis(rng)
            aligned = [k for k in range(3) if np.array_equal(unit, UNIT_AXES[k])]
            if kind == "revolute":
                idx = model.add_revolute(parent, axis, placement, body_mp, name)
                jm = [pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ][aligned[0]]() if aligned else pin.JointModelRevoluteUnaligned(unit)
            else:
                idx = model.add_prismatic(parent, axis, placement, body_mp, name)
                jm = [pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ][aligned[0]]() if aligned else pin.JointModelPrismaticUnaligned(unit)
            j = pin_model.addJoint(pj, jm, pX * X, name)
            pin_model.appendBodyToJoint(j, pin.Inertia(body[0], body[1], body[2]), pin.SE3.Identity())
            body_joint.append(j)
            body_in_joint.append(pin.SE3.Identity())
            anchored.append(False)
        assert idx == i, (idx, i)
        parents.append(parent)
        kinds.append(kind)
        axes.append(axis)
        placements.append(T)
        bodies.append(body)
        as_tuple.append(use_tuple)

    twin = Twin(model, pin_model, floating, parents, kinds, axes, placements, bodies, body_joint, body_in_joint, g, as_tuple)
    # The q/v layouts coincide by construction (1-DoF joints and the free flyer, added in body order).
    assert model.nq == pin_model.nq and model.nv == pin_model.nv, (model.nq, pin_model.nq, model.nv, pin_model.nv)
    assert model.nbodies == n_bodies
    return twin


# --------------------------------------------------------------------------------------------------
# Hypothesis helpers
# --------------------------------------------------------------------------------------------------


def body_counts(max_bodies: int = 200):
    """Mostly small trees (1-8 bodies), sometimes medium (9-40), rarely large (41-max_bodies)."""

    @st.composite
    def counts(draw):
        size_class = draw(st.integers(0, 19))
        if size_class < 14 or max_bodies <= 8:
            return draw(st.integers(1, min(8, max_bodies)))
        if size_class < 18 or max_bodies <= 40:
            return draw(st.integers(9, min(40, max_bodies)))
        return draw(st.integers(41, max_bodies))

    return counts()


def random_model(draw, n_bodies: int, floating: bool, **kwargs) -> Twin:
    """Inside a @st.composite: draw a seed and build the twin (keyword arguments go to build_twin)."""
    seed = draw(st.integers(0, 2**32 - 1), label="model_seed")
    return build_twin(np.random.default_rng(seed), n_bodies, floating, **kwargs)


@st.composite
def twins(draw, max_bodies: int = 200, floating: bool | None = None, **kwargs) -> Twin:
    """A random twin: size from body_counts(max_bodies), fixed or floating base (drawn unless given)."""
    n = draw(body_counts(max_bodies), label="n_bodies")
    fl = draw(st.booleans(), label="floating") if floating is None else floating
    return random_model(draw, n, fl, **kwargs)


def rngs():
    """A seeded numpy Generator for random states (hypothesis shrinks the seed)."""
    return st.integers(0, 2**32 - 1).map(np.random.default_rng)
