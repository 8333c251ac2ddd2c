"""Benchmark models built twice from the same numbers: as a `legkit.Model` and as a `pinocchio.Model`.

Every builder returns ``(lk_model, pin_model)``. A model is first described as a list of `Link`s (parent,
joint axis, placement in the parent body frame, box body), numbered parent before child *and* depth-first,
so legkit's body order and Pinocchio's joint order coincide and q / v / tau vectors are literally the same
in both libraries:

* fixed base: legkit body i (i >= 1) is Pinocchio joint i; the base is Pinocchio's universe (joint 0),
  whose inertia neither library uses;
* floating base: legkit body 0 (the free-flyer base) is Pinocchio joint 1, a `JointModelFreeFlyer`
  carrying the base inertia, and legkit body i is Pinocchio joint i + 1. Both use
  q = [x, y, z, qx, qy, qz, qw] and v = [v_lin, v_ang] in the base frame.

All joint axes are +x, +y or +z of their joint frame, so Pinocchio gets its specialised `JointModelRX/RY/RZ`
(what a Pinocchio user would write), and all placements rotate by multiples of 90 degrees (exact matrices).

Models (`MODELS` maps a name to its builder):

* ``tree``: a SuperBot-like modular tree, 21 modules x 3 revolute joints = 63 DoF (`superbot_tree`);
* ``chain6`` ... ``chain1024``: serial revolute chains, axes cycling y, x, z, 0.1 m box links (`chain`);
* ``quadruped``: a floating-base quadruped, 6 + 12 DoF (`quadruped`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
import pinocchio as pin

import legkit as lk

AXES = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}
PIN_REVOLUTE = {"x": pin.JointModelRX, "y": pin.JointModelRY, "z": pin.JointModelRZ}

CHAIN_LENGTHS = (6, 12, 18, 64, 256, 512, 1024)


# --------------------------------------------------------------------------------------------------
# Exact quarter-turn rotations
# --------------------------------------------------------------------------------------------------


def rot(axis: str, quarter_turns: int) -> np.ndarray:
    """Rotation by quarter_turns x 90 degrees about a coordinate axis, with exact 0 / +-1 entries."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][quarter_turns % 4]
    i = "xyz".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    R = np.zeros((3, 3))
    R[i, i] = 1.0
    R[j, j], R[j, k] = c, -s
    R[k, j], R[k, k] = s, c
    return R


# --------------------------------------------------------------------------------------------------
# A model description shared by both builders
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Box:
    """A solid box of `mass` kg, edge lengths `size`, centred at `center` (axis-aligned in its body frame)."""

    mass: float
    size: tuple[float, float, float]
    center: tuple[float, float, float]

    def legkit(self) -> lk.MassProperties:
        return lk.MassProperties.solid_box(self.mass, np.array(self.size), center=np.array(self.center))

    def pinocchio(self) -> pin.Inertia:
        a, b, c = self.size
        about_com = self.mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
        return pin.Inertia(self.mass, np.array(self.center), about_com)


@dataclass(frozen=True)
class Link:
    """A body on a revolute joint about `axis` ("x", "y" or "z") placed at (R, t) in body `parent`."""

    parent: int  # legkit body index (0 = base)
    axis: str
    R: np.ndarray
    t: np.ndarray
    body: Box
    name: str


def build(links: list[Link], floating: bool = False, base: Box | None = None) -> tuple[lk.Model, pin.Model]:
    """Both models from one description; links must be in depth-first pre-order (checked)."""
    _check_depth_first([link.parent for link in links])
    lk_model = lk.Model(floating_base=floating, base=base.legkit() if base is not None else None)
    pin_model = pin.Model()
    pin_model.name = "bench"
    offset = 0
    if floating:
        assert base is not None, "a floating base needs a body"
        root = pin_model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
        pin_model.appendBodyToJoint(root, base.pinocchio(), pin.SE3.Identity())
        offset = 1
    for link in links:
        i = lk_model.add_revolute(link.parent, AXES[link.axis], (link.R, link.t), link.body.legkit(), link.name)
        parent_joint = link.parent + offset if (link.parent > 0 or floating) else 0
        j = pin_model.addJoint(parent_joint, PIN_REVOLUTE[link.axis](), pin.SE3(link.R, link.t), link.name)
        pin_model.appendBodyToJoint(j, link.body.pinocchio(), pin.SE3.Identity())
        assert j == i + offset, (i, j)
    assert lk_model.nq == pin_model.nq and lk_model.nv == pin_model.nv
    return lk_model, pin_model


def _check_depth_first(parents: list[int]) -> None:
    """Body i + 1's parent must be on the path from the root to body i (depth-first pre-order)."""
    path = [0]
    for i, p in enumerate(parents, start=1):
        while path and path[-1] != p:
            path.pop()
        if not path:
            raise ValueError(f"body {i} (parent {p}) breaks depth-first order")
        path.append(i)


# --------------------------------------------------------------------------------------------------
# 1. SuperBot-like modular tree
# --------------------------------------------------------------------------------------------------

# A module is 0.1 m long along its own +x: an end block, a middle block and an end block on three joints in
# series: pitch (y) at the module's entry face, roll (x, the long axis) 0.025 m further, pitch (y) 0.05 m
# further; the module's exit face is 0.025 m past the last joint.
END_BLOCK = Box(0.05, (0.025, 0.05, 0.05), (0.0125, 0.0, 0.0))
MIDDLE_BLOCK = Box(0.10, (0.05, 0.03, 0.03), (0.025, 0.0, 0.0))
MODULE_JOINTS = (("y", 0.0, END_BLOCK), ("x", 0.025, MIDDLE_BLOCK), ("y", 0.05, END_BLOCK))
END_FACE = 0.025  # exit face of the last end block, along its +x
SIDE_FACE = 0.025  # the +-y side faces of an end block (half its width)
BRANCHES = 4
MODULES_PER_BRANCH = 5


def _module(links: list[Link], parent: int, R: np.ndarray, t: np.ndarray, name: str) -> tuple[int, int]:
    """Appends one module entering at (R, t) in body `parent`; returns its (first, last) end-block indices."""
    first = len(links) + 1
    for k, (axis, offset, box) in enumerate(MODULE_JOINTS):
        if k == 0:
            placement = (R, np.asarray(t, dtype=float))
        else:
            placement = (np.eye(3), np.array([offset, 0.0, 0.0]))
        links.append(Link(parent, axis, placement[0], placement[1], box, f"{name}_j{k}"))
        parent = len(links)
    return first, parent


def superbot_links() -> list[Link]:
    """21 modules: a root module on the fixed base and 4 branches of 5 modules, in depth-first order.

    Branches 0 and 1 leave the root module's last end block through its +y / -y side faces, branches 2 and
    3 its first end block likewise; a branch's first module points along the face normal. Along a branch each
    module plugs into the previous one's exit face (+x), turned about that face normal (x) by 90 degrees at
    every other connection (0, 90, 0, 90, ...), as SuperBot modules are chained to alternate pitch planes.
    """
    links: list[Link] = []
    first, last = _module(links, 0, np.eye(3), np.zeros(3), "root")
    # Depth-first pre-order: the root's three bodies, then the subtrees hanging off the last end block
    # (deepest first), then those off the first end block; each branch entire before the next.
    faces = [
        (last, rot("z", 1), np.array([0.0125, SIDE_FACE, 0.0])),
        (last, rot("z", -1), np.array([0.0125, -SIDE_FACE, 0.0])),
        (first, rot("z", 1), np.array([0.0125, SIDE_FACE, 0.0])),
        (first, rot("z", -1), np.array([0.0125, -SIDE_FACE, 0.0])),
    ]
    for b, (host, R_face, t_face) in enumerate(faces):
        parent, R, t = host, R_face, t_face
        for m in range(MODULES_PER_BRANCH):
            twist = rot("x", m % 2)  # 90 degrees about the connection's face normal, alternating
            _, parent = _module(links, parent, R @ twist, t, f"b{b}m{m}")
            R, t = np.eye(3), np.array([END_FACE, 0.0, 0.0])
    return links


def superbot_tree() -> tuple[lk.Model, pin.Model]:
    """The 63-DoF SuperBot-like tree on a fixed base."""
    return build(superbot_links())


# --------------------------------------------------------------------------------------------------
# 2. Revolute chains
# --------------------------------------------------------------------------------------------------

LINK = Box(0.5, (0.03, 0.03, 0.1), (0.0, 0.0, 0.05))


def chain_links(n: int) -> list[Link]:
    """n links of 0.1 m along z, joint axes cycling y, x, z; link 0 at the base origin."""
    return [
        Link(i, "yxz"[i % 3], np.eye(3), np.array([0.0, 0.0, 0.1 if i > 0 else 0.0]), LINK, f"link{i}")
        for i in range(n)
    ]


def chain(n: int) -> tuple[lk.Model, pin.Model]:
    """A fixed-base revolute chain of n links."""
    return build(chain_links(n))


# --------------------------------------------------------------------------------------------------
# 3. Floating-base quadruped
# --------------------------------------------------------------------------------------------------

TORSO = Box(8.0, (0.5, 0.25, 0.1), (0.0, 0.0, 0.0))
HIP = Box(0.6, (0.08, 0.06, 0.06), (0.0, 0.0, 0.0))
THIGH = Box(1.0, (0.04, 0.04, 0.22), (0.0, 0.0, -0.11))
SHANK = Box(0.25, (0.025, 0.025, 0.22), (0.0, 0.0, -0.11))


def quadruped_links() -> list[Link]:
    """4 legs x (hip abduction x, hip flexion y, knee y) at the torso corners, legs hanging along -z."""
    links: list[Link] = []
    for name, sx, sy in (("fl", 1, 1), ("fr", 1, -1), ("hl", -1, 1), ("hr", -1, -1)):
        hip = len(links) + 1
        links.append(Link(0, "x", np.eye(3), np.array([0.22 * sx, 0.09 * sy, 0.0]), HIP, f"{name}_hip_abad"))
        links.append(Link(hip, "y", np.eye(3), np.array([0.0, 0.07 * sy, 0.0]), THIGH, f"{name}_hip_flex"))
        links.append(Link(hip + 1, "y", np.eye(3), np.array([0.0, 0.0, -0.22]), SHANK, f"{name}_knee"))
    return links


def quadruped() -> tuple[lk.Model, pin.Model]:
    """The floating-base quadruped: free-flyer torso + 12 revolute joints (nq 19, nv 18)."""
    return build(quadruped_links(), floating=True, base=TORSO)


# --------------------------------------------------------------------------------------------------

MODELS: dict[str, Callable[[], tuple[lk.Model, pin.Model]]] = {
    "tree": superbot_tree,
    **{f"chain{n}": partial(chain, n) for n in CHAIN_LENGTHS},
    "quadruped": quadruped,
}


def random_state(
    lk_model: lk.Model, rng: np.random.Generator, batch: tuple[int, ...] = ()
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, v, tau) of shapes batch + (nq,), batch + (nv,), batch + (nv,): joint angles in [-pi, pi], a random
    base pose with a unit quaternion for a floating base, v and tau standard normal."""
    nq, nv = lk_model.nq, lk_model.nv
    q = rng.uniform(-np.pi, np.pi, batch + (nq,))
    if lk_model.floating_base:
        q[..., :3] = rng.uniform(-1.0, 1.0, batch + (3,))
        quat = rng.normal(size=batch + (4,))
        q[..., 3:7] = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    v = rng.normal(size=batch + (nv,))
    tau = rng.normal(size=batch + (nv,))
    return q, v, tau
