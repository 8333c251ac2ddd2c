"""A robot's mirror image through its sagittal plane, for gaits transcribed over half a cycle.

A symmetric gait's second half is the mirror image of its first ([Hardt 2002, Sect. 4.1] names "periodicity or
mirror periodicity"): the amble's LF+LH, LF+RH is followed by RF+RH, RF+LH, the biped's left stance by the
right. Mirroring reflects the world through the x-z plane (y -> -y) and swaps left and right. In coordinates
it is a signed permutation: the base's y, the quaternion's x and z and the angular velocity's x and z change
sign; each joint takes its mirror joint's coordinate, with the sign that makes the two bodies mirror images
(+ for a pitch joint whose axis is y on both sides, - for a roll or yaw joint). `sagittal_mirror` finds the
signs from the model's kinematics and checks that the model is symmetric.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

import legkit as lk

#: The reflection through the x-z plane.
REFLECTION = np.diag([1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Mirror:
    """The mirror of q (nq,) is ``q_sign * q[q_order]``, of v (nv,) ``v_sign * v[v_order]``; a foot's mirror is
    ``feet[name]``. Mirroring twice is the identity."""

    q_order: np.ndarray
    q_sign: np.ndarray
    v_order: np.ndarray
    v_sign: np.ndarray
    feet: Mapping[str, str] = field(default_factory=dict)

    def q(self, q: np.ndarray) -> np.ndarray:
        """Mirrored configurations (..., nq)."""
        return self.q_sign * np.asarray(q)[..., self.q_order]

    def v(self, v: np.ndarray) -> np.ndarray:
        """Mirrored velocities or accelerations (..., nv)."""
        return self.v_sign * np.asarray(v)[..., self.v_order]

    def control_order(self, actuated: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(order, sign): mirrored controls are ``sign * u[..., order]`` for controls u of the velocity
        coordinates ``actuated`` (which the mirror must map onto themselves)."""
        column = {int(v): j for j, v in enumerate(actuated)}
        return np.array([column[int(self.v_order[v])] for v in actuated], dtype=np.int64), self.v_sign[actuated]

    def contacts(self, contacts: Sequence[str]) -> tuple[str, ...]:
        """The mirrored feet, in the same order."""
        return tuple(self.feet[name] for name in contacts)

    @staticmethod
    def vectors(vectors: np.ndarray) -> np.ndarray:
        """World forces (..., 3) mirrored: y changes sign."""
        return vectors * np.array([1.0, -1.0, 1.0])

    @staticmethod
    def axial(vectors: np.ndarray) -> np.ndarray:
        """Axial vectors (..., 3) such as torques, mirrored: x and z change sign."""
        return vectors * np.array([-1.0, 1.0, -1.0])


def sagittal_mirror(model: lk.Model, bodies: Mapping[str, str], feet: Mapping[str, str] | None = None,
                    seed: int = 0) -> Mirror:
    """The mirror of `model` through its sagittal plane: `bodies` maps body names to their mirror bodies' (one
    side is enough; bodies not named are their own mirror, on the plane), `feet` foot names likewise.

    Each joint's sign is the one under which the moved bodies' centres of mass are mirror images; a joint for
    which neither sign is, or a whole random configuration whose mirror is not the mirror image, raises
    ValueError (the model is not symmetric under `bodies`)."""
    names = list(model.names)
    pairs = _involution(bodies)
    unknown = sorted(set(pairs) - set(names))
    if unknown:
        raise ValueError(f"bodies: the model has no bodies {unknown}")
    image = np.array([names.index(pairs.get(name, name)) for name in names])
    idx_q, idx_v = np.asarray(model.idx_q), np.asarray(model.idx_v)
    q_order, v_order = np.arange(model.nq), np.arange(model.nv)
    q_sign, v_sign = np.ones(model.nq), np.ones(model.nv)
    joints = [i for i in range(1, model.nbodies) if model.joint_type(i) != "fixed"]
    if model.floating_base:
        q_sign[[1, 3, 5]] = -1.0  # y; the quaternion's x and z
        v_sign[[1, 3, 5]] = -1.0  # v_y; omega_x and omega_z
    for i in joints:
        j = image[i]
        if model.joint_type(j) != model.joint_type(i):
            raise ValueError(f"bodies: {names[i]!r} moves on a {model.joint_type(i)} joint, its mirror {names[j]!r} on a {model.joint_type(j)}")
        q_order[idx_q[i]], v_order[idx_v[i]] = idx_q[j], idx_v[j]
        q_sign[idx_q[i]] = v_sign[idx_v[i]] = _joint_sign(model, image, idx_q[i], idx_q[j], names[i])
    mirror = Mirror(q_order, q_sign, v_order, v_sign, {} if feet is None else _involution(feet))
    q = model.neutral()
    rng = np.random.default_rng(seed)
    q[idx_q[joints]] = rng.uniform(-0.6, 0.6, len(joints))
    if model.floating_base:
        q[:3] = rng.uniform(-0.5, 0.5, 3)
        turn = rng.normal(size=4)
        q[3:7] = turn / np.linalg.norm(turn)
    if not np.allclose(_coms(model, mirror.q(q))[image] @ REFLECTION, _coms(model, q), atol=1e-9):
        raise ValueError("bodies: the model is not mirror-symmetric under this pairing (a random configuration and its "
                         "mirror are not mirror images)")
    return mirror


def side_mirror(model: lk.Model, sides: Mapping[str, str]) -> Mirror:
    """`sagittal_mirror` for a robot whose left and right bodies and feet are named alike but for their side:
    `sides` maps each left prefix to its right one (e.g. {"l": "r"} pairs bodies "l_thigh", "r_thigh" and feet
    "l", "r"; {"lf": "rf", "lh": "rh"} a quadruple's legs)."""
    bodies = {name: right + name[len(left):] for name in model.names for left, right in sides.items() if name.startswith(left + "_")}
    return sagittal_mirror(model, bodies, dict(sides))


def _joint_sign(model: lk.Model, image: np.ndarray, own: int, other: int, name: str) -> float:
    """+1 or -1: the sign under which turning coordinate `own` and, mirrored, coordinate `other` by the same
    amount moves every body's COM to its mirror image's mirror (checked at the neutral configuration)."""
    for sign in (1.0, -1.0):
        q, q_mirror = model.neutral(), model.neutral()
        q[own], q_mirror[other] = 0.5, sign * 0.5
        if np.allclose(_coms(model, q_mirror)[image] @ REFLECTION, _coms(model, q), atol=1e-9):
            return sign
    raise ValueError(f"bodies: the joint of {name!r} and its mirror's do not move their bodies as mirror images")


def _coms(model: lk.Model, q: np.ndarray) -> np.ndarray:
    """(nbodies, 3) world centres of mass."""
    poses = np.asarray(lk.forward_kinematics(model, q))
    coms = np.array([model.body(i).com for i in range(model.nbodies)])
    return np.einsum("bij,bj->bi", poses[:, :3, :3], coms) + poses[:, :3, 3]


def _involution(pairs: Mapping[str, str]) -> dict[str, str]:
    """pairs completed both ways."""
    both = dict(pairs)
    both.update({b: a for a, b in pairs.items()})
    return both
