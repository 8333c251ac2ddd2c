"""Type stubs of the compiled module ``legkit._core``."""

import os
import pathlib
from collections.abc import Sequence
from typing import Any, Literal, overload

import numpy as np
import numpy.typing as npt

_Vector = npt.ArrayLike
_Matrix = npt.ArrayLike

COMPILED_TARGET_FEATURES: str
"""The target features the extension was compiled for, comma-separated in Rust's names ("avx,avx2,..."):
what ``-C target-cpu`` enabled; ``import legkit`` checks them against the CPU (legkit/_build.py)."""

class MassProperties:
    """Mass, centre of mass and rotational inertia about the centre of mass, all in one frame.

    ``+`` composes bodies by the parallel-axis theorem (not the mass-weighted average of inertias);
    ``-`` is its exact inverse and raises ValueError when the difference would not be a physical body
    (``a - a`` gives ``zero()``). ``==`` compares with ``isclose``'s default tolerances.
    """

    def __init__(self, mass: float, com: _Vector, inertia: _Matrix) -> None: ...
    @staticmethod
    def zero() -> MassProperties: ...
    @staticmethod
    def point(mass: float, position: _Vector) -> MassProperties: ...
    @staticmethod
    def solid_box(mass: float, size: _Vector, center: _Vector | None = None, rotation: _Matrix | None = None) -> MassProperties:
        """A solid box of uniform density with full edge lengths ``size``, centred at ``center``, rotated by ``rotation``."""
    @staticmethod
    def from_points(masses: _Vector, positions: _Matrix) -> MassProperties: ...
    @property
    def mass(self) -> float: ...
    @property
    def com(self) -> np.ndarray: ...
    @property
    def inertia(self) -> np.ndarray:
        """3x3 inertia about the centre of mass."""
    def inertia_about(self, point: _Vector) -> np.ndarray: ...
    def transformed(self, rotation: _Matrix, translation: _Vector | None = None) -> MassProperties:
        """Express in the parent frame of ``x_parent = R x + t``: pass ``(R, t)`` or one 4x4 matrix."""
    def isclose(self, other: MassProperties, rtol: float = 1e-9, atol: float = 1e-12) -> bool: ...
    def __add__(self, other: MassProperties) -> MassProperties: ...
    def __radd__(self, other: int) -> MassProperties: ...
    def __sub__(self, other: MassProperties) -> MassProperties: ...
    def __eq__(self, other: object) -> bool: ...

_Placement = npt.ArrayLike | tuple[npt.ArrayLike, npt.ArrayLike]
_Body = int | str
_Limits = tuple[float, float] | Sequence[float] | dict[str, float]

class Model:
    """A kinematic tree. Body 0 is the base: fixed to the world, or a free flyer with
    q = [x, y, z, qx, qy, qz, qw] and v = [v_lin, v_ang] in the base frame. Every other body hangs off a
    revolute, prismatic, helical or fixed joint whose frame is placed (4x4, or (R, t)) in its parent's frame; the
    body's frame is the joint frame after the joint's motion. Bodies are numbered parent first. Bodies and joints
    are named (apart: a joint may share a link's name); a body's joint is named after the body unless a loader names
    it, the base's joint "root_joint"."""

    def __init__(
        self, floating_base: bool = False, base: MassProperties | None = None, base_name: str = "base",
        gravity: _Vector | None = None,
    ) -> None: ...
    def add_revolute(
        self, parent: _Body, axis: _Vector, placement: _Placement | None = None, body: MassProperties | None = None,
        name: str | None = None, limits: _Limits | None = None,
    ) -> int:
        """limits: (lower, upper) in rad, or a dict with any of lower, upper (rad, +-inf for none), effort (N m),
        velocity (rad/s) (> 0, inf for none). Enforced by Simulation (range, effort); ignored by the dynamics."""
    def add_prismatic(
        self, parent: _Body, axis: _Vector, placement: _Placement | None = None, body: MassProperties | None = None,
        name: str | None = None, limits: _Limits | None = None,
    ) -> int:
        """limits as for add_revolute, in m, N and m/s."""
    def add_helical(
        self, parent: _Body, axis: _Vector, pitch: float, placement: _Placement | None = None, body: MassProperties | None = None,
        name: str | None = None, limits: _Limits | None = None,
    ) -> int:
        """Turns by q about axis and moves pitch * q (m/rad) along it; limits as for add_revolute. The tree engine
        simulates it; backend="rapier" refuses it (RuntimeError)."""
    def add_spherical(
        self, parent: _Body, placement: _Placement | None = None, body: MassProperties | None = None, name: str | None = None
    ) -> int:
        """A ball joint: q a unit quaternion [qx, qy, qz, qw], v the angular velocity in the body's frame (Pinocchio's
        JointModelSpherical). The tree engine simulates it (per-axis damping, armature, velocity servos; no position
        servo); backend="rapier" refuses it."""
    def add_fixed(
        self, parent: _Body, placement: _Placement | None = None, body: MassProperties | None = None, name: str | None = None
    ) -> int: ...
    @property
    def nq(self) -> int: ...
    @property
    def nv(self) -> int: ...
    @property
    def nbodies(self) -> int: ...
    @property
    def floating_base(self) -> bool: ...
    @property
    def parents(self) -> list[int]:
        """Parent of each body; the base is its own parent (``parents[0] == 0``), as in Pinocchio."""
    @property
    def names(self) -> list[str]:
        """Each body's name (a URDF's link names, an MJCF's body names), in body order."""
    @property
    def joint_names(self) -> list[str]:
        """The names of the joints with coordinates, in q (and v) order: Pinocchio's ``model.names[1:]`` for a URDF,
        a floating base's joint first as "root_joint"; MuJoCo's for an MJCF (a free joint off the floating base as
        four: its name, then ":y", ":z" and ":rotation")."""
    def joint_index(self, name: str) -> int:
        """The body the joint named ``name`` moves (Pinocchio's ``getJointId``), so its coordinates start at
        ``idx_q[i]`` and ``idx_v[i]``; IndexError naming ``name`` if no joint has it."""
    @property
    def gravity(self) -> np.ndarray: ...
    @property
    def armature(self) -> np.ndarray:
        """(nv,) read-only: reflected rotor inertia per velocity coordinate (Pinocchio's model.armature); RNEA, CRBA, kinetic energy,
        ABA, Minv and Simulation use M + diag(armature). Set whole: an (nv,) array, or one number for every joint."""
    @armature.setter
    def armature(self, value: npt.ArrayLike) -> None: ...
    @property
    def damping(self) -> np.ndarray:
        """(nv,) read-only: viscous damping per velocity coordinate; Simulation applies -damping v, the dynamics
        functions ignore it (as Pinocchio's). Set as armature."""
    @damping.setter
    def damping(self, value: npt.ArrayLike) -> None: ...
    @property
    def total_mass(self) -> float: ...
    @property
    def idx_q(self) -> list[int]: ...
    @property
    def idx_v(self) -> list[int]: ...
    def joint_type(self, body: _Body) -> str: ...
    def joint_axis(self, body: _Body) -> np.ndarray | None: ...
    def joint_pitch(self, body: _Body) -> float | None: ...
    def with_body(self, body: _Body, mass_properties: MassProperties) -> Model:
        """A copy in which body has these mass properties (own frame); joints, placements, limits, shapes unchanged."""
    def limits(self, body: _Body) -> dict[str, float] | None:
        """{lower, upper, effort, velocity} of the body's joint (+-inf where unbounded), None if it has no limits."""
    def body(self, body: _Body) -> MassProperties: ...
    def placement(self, body: _Body) -> np.ndarray: ...
    def neutral(self) -> np.ndarray: ...
    def colliders(
        self, shapes: dict[int | str, _ShapeSpec] | None = None
    ) -> list[tuple[int, Literal["box", "sphere", "capsule", "cylinder", "convex"], tuple[float, ...] | np.ndarray, np.ndarray]]:
        """What ``Simulation(model, shapes=shapes)`` collides with: (body, kind, size, placement (4, 4) in the body
        frame); size: box full edge lengths, sphere (radius,), capsule/cylinder (half_height, radius) along z,
        convex the hull's vertices (n, 3)."""
    @staticmethod
    def from_urdf(
        path_or_xml: str | os.PathLike[str], floating_base: bool = False, strict: bool = False,
        package_dirs: Sequence[str | os.PathLike[str]] | None = None,
    ) -> Model:
        """A model from a URDF path or XML string; bodies are named after links, the root link is the base,
        joints after the URDF's joints. q and v are Pinocchio's (``pin.buildModelFromUrdf``, with
        ``pin.JointModelFreeFlyer()`` for floating_base=True), coordinate for coordinate: joints depth first from the
        root, a link's children in the order of their joints' names; but a continuous joint's q is its angle, where
        Pinocchio's is (cos, sin).
        What exporters write and Pinocchio loads (non-physical inertias, effort="0") loads as written with
        a UrdfWarning naming the element, or raises ValueError if strict. A string starting with "<" (after a byte
        order mark and blanks) is XML, anything else a path; a path that is not a regular file (a FIFO, a device)
        is refused before it is opened. Ctrl-C interrupts the load. A ``floating`` joint becomes three slides along
        its joint frame's axes and a ball joint (q Pinocchio's free-flyer q; the linear rate in the joint frame), refused
        out of the root link with floating_base=True; the extension ``spherical`` a ball joint, with a UrdfWarning.
        See docs/urdf_to_simulation.md."""
    @staticmethod
    def from_mjcf(path_or_xml: str | os.PathLike[str], floating_base: bool | None = None, strict: bool = False) -> Model:
        """A model from a MuJoCo MJCF path or XML string (``load_mjcf`` also gives its joints, actuators and
        options): bodies in MuJoCo's order, hinge and slide joints with q equal to MuJoCo's qpos, a top-level free
        joint as the free-flyer base (``floating_base=None``: as the file says; False welds it, True frees the single
        top-level body), default classes, includes, every orientation form with ``<compiler angle>`` (degrees
        unless set), inertias from ``<inertial>`` or from geoms as MuJoCo's compiler, collision shapes from geoms,
        ``<option gravity>``; ball joints become spherical joints. What legkit does not model (tendons, equality
        constraints, sensors, joint stiffness, ...) loads with an MjcfWarning naming it, or raises ValueError if
        strict. Ctrl-C interrupts the load. See docs/mjcf.md."""

def resolve_mesh(
    filename: str, urdf: str | os.PathLike[str] | None = None, package_dirs: Sequence[str | os.PathLike[str]] | None = None,
) -> pathlib.Path:
    """The file a URDF's mesh ``filename`` names, as ``Model.from_urdf`` finds it: ``package://name/rest`` in
    ``package_dirs`` (folders holding packages, or a package itself), then ROS_PACKAGE_PATH, then AMENT_PREFIX_PATH's
    share/ folders, then the folders above the file ``urdf``; relative names against ``urdf``'s folder.
    FileNotFoundError naming where it looked; ValueError naming ``filename`` for a name with ``..`` (which would
    climb out of its package) or a symbolic link out of the package to a file of another kind."""

class UrdfWarning(UserWarning):
    """A URDF loaded as written although it is not quite valid; the message names the element."""

class MjcfWarning(UserWarning):
    """An MJCF loaded without something legkit does not model (a tendon, a sensor, a joint's stiffness, ...); the
    message names it."""

class Mjcf:
    """An MJCF file read into a Model, with its joints, joint actuators, options and floor."""
    @property
    def model(self) -> Model: ...
    @property
    def joints(self) -> list[dict[str, Any]]:
        """The kept joints in MuJoCo's order: {name, type ("hinge", "slide", "free"), body, idx_q, idx_v}."""
    @property
    def actuators(self) -> list[dict[str, Any]]:
        """The joint actuators: {name, joint, dof, gear, gain (3), bias (3), ctrlrange, forcerange} (None: not limited)."""
    @property
    def timestep(self) -> float:
        """``<option timestep>`` (s; MuJoCo's default 0.002)."""
    @property
    def gravity(self) -> np.ndarray:
        """``<option gravity>`` (m/s^2), also the model's gravity."""
    @property
    def ground(self) -> Ground | None:
        """The floor: the world body's first colliding plane geom, placed as in MuJoCo, with its sliding friction;
        None when the file has none."""
    def simulation(self, **options: Any) -> Simulation:
        """``Simulation(model, dt=timestep, ground=ground, **options)``: the model on its own floor at the file's
        timestep (``options`` are Simulation's; ``dt`` and ``ground`` override the file's)."""
    @property
    def warnings(self) -> list[str]:
        """What was loaded with a warning (also raised as MjcfWarnings)."""
    def actuator_torques(self, q: npt.ArrayLike, v: npt.ArrayLike, ctrl: npt.ArrayLike) -> np.ndarray:
        """The joint torques (nv,) of controls ``ctrl`` (one per actuator) at (q, v), as MuJoCo's qfrc_actuator:
        force = gain ctrl + bias (affine in gear q and gear v), ctrl and force clamped, torque gear force."""

def load_mjcf(path_or_xml: str | os.PathLike[str], floating_base: bool | None = None, strict: bool = False) -> Mjcf:
    """The MJCF as an Mjcf (see Model.from_mjcf for what is read)."""

def forward_kinematics(model: Model, q: npt.ArrayLike) -> np.ndarray:
    """World pose (4x4) of every body: (..., nbodies, 4, 4)."""
def rnea(model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, f_ext: npt.ArrayLike | None = None) -> np.ndarray:
    """Inverse dynamics tau = M a + C v + g - sum J^T f_ext; f_ext is (..., nbodies, 6), [f, n] in each body's frame."""
def aba(model: Model, q: npt.ArrayLike, v: npt.ArrayLike, tau: npt.ArrayLike, f_ext: npt.ArrayLike | None = None) -> np.ndarray:
    """Forward dynamics by the O(n) articulated-body algorithm: (..., nv)."""
def rnea_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, f_ext: npt.ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(dtau/dq, dtau/dv) of ``rnea``, each (..., nv, nv); q on its tangent space (a free-flyer base perturbed as
    q (+) dq with dq = [dv_lin, dw] in the base frame, as ``integrate``), as Pinocchio's computeRNEADerivatives.
    dtau/da is ``crba``."""
def rnea_second_order_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(d2tau_dqdq, d2tau_dvdv, d2tau_dqdv, d2tau_dadq) of ``rnea``, each (..., nv, nv, nv): entry [i, j, k] is the slope
    along the third index of a first derivative (d/dq_k of dtau_i/dq_j, d/dv_k of dtau_i/dv_j, d/dv_k of dtau_i/dq_j,
    d/dq_k of M_ij); q on its tangent space, as Pinocchio's ComputeRNEASecondOrderDerivatives. The Hessian of a
    multiplier's lam^T tau: ``np.einsum("i,ijk->jk", lam, d2tau_dqdq)``."""
def aba_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, tau: npt.ArrayLike, f_ext: npt.ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(da/dq, da/dv, da/dtau = M^-1) of ``aba``, each (..., nv, nv); q on its tangent space, as Pinocchio's
    computeABADerivatives. A singular mass matrix raises as in ``aba``."""
def centroidal_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(dh/dq, dhdot/dq, dhdot/dv, dhdot/da = dh/dv = A_G) of ``centroidal_momentum`` h and ``centroidal_momentum_rate``
    hdot (gravity excluded, as Pinocchio's), each (..., 6, nv), rows [linear; angular about the COM] in world axes; q on
    its tangent space as in ``rnea_derivatives``, as Pinocchio's computeCentroidalDynamicsDerivatives."""
def center_of_mass_jacobian(model: Model, q: npt.ArrayLike) -> np.ndarray:
    """d(center_of_mass)/dq, (..., 3, nv) in world axes, q on its tangent space (Pinocchio's jacobianCenterOfMass)."""
def center_of_mass_hessian(model: Model, q: npt.ArrayLike, weights: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(Hessian (..., nv, nv), gradient (..., nv)) with respect to q (on its tangent space, as ``rnea_derivatives``; entry
    [e, d] the slope along q_d of the gradient's entry e) of ``weights`` (..., 3) . the world centre of mass."""
def centroidal_momentum_hessian(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, weights: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(qq (..., nv, nv), qv (..., nv, nv), q-gradient (..., nv)) of ``weights`` (..., 6) . ``centroidal_momentum`` h
    ([linear; angular about the COM]): qq [e, d] the slope along q_d of the gradient's entry e (q on its tangent space),
    qv [d, e] = d2/dq_d dv_e; vv is zero (h is linear in v)."""
def crba(model: Model, q: npt.ArrayLike) -> np.ndarray:
    """Joint-space mass matrix M(q): (..., nv, nv)."""
def minv(model: Model, q: npt.ArrayLike) -> np.ndarray:
    """M(q)^-1 by the O(n) articulated-body recursion: (..., nv, nv)."""
_Frame = Literal["local", "world", "local_world_aligned"]
_ContactPoints = Sequence[tuple[_Body, npt.ArrayLike]]

def jacobian(model: Model, q: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None, frame: _Frame = "local_world_aligned") -> np.ndarray:
    """6 x nv Jacobian (rows [linear; angular]) of the frame at `point` on `body`: (..., 6, nv). On q's tangent space, the
    "local" Jacobian is also the derivative of the frame's placement."""
def jacobian_time_variation(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None, frame: _Frame = "local_world_aligned"
) -> np.ndarray:
    """dJ/dt of ``jacobian`` along the velocity v (Pinocchio's getFrameJacobianTimeVariation): (..., 6, nv). In
    "local_world_aligned" the point's classical acceleration is J a + dJ/dt v + w x v_point."""
def kinematic_hessian(
    model: Model, q: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None, frame: _Frame = "local_world_aligned",
) -> np.ndarray:
    """d/dq_d of entry [r, a] of ``jacobian`` at [r, a, d] (Pinocchio's getJointKinematicHessian; q on its tangent space, as
    ``rnea_derivatives``), in "world" or "local_world_aligned" ("local" raises ValueError): (..., 6, nv, nv). Along q_d, the slope of
    w . J_lin (the gradient of w . position): ``np.einsum("r,rad->ad", w, H[:3])``."""
def point_velocity_hessian(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None, weights: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """(Hessian (..., nv, nv), gradient (..., nv)) with respect to q (on its tangent space, as ``rnea_derivatives``; entry
    [e, d] the slope along q_d of the gradient's entry e) of ``weights`` (..., 3) . the world velocity J_lin(q) v of
    `point` on `body`: the curvature of a load's virtual power F . J(q) v."""
def point_acceleration_hessian(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None, weights: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(qq, qv, vv, qa, q-gradient) of ``weights`` (..., 3) . the classical world acceleration of `point` on `body` (as
    ``point_accelerations``) with respect to q (on its tangent space, as ``rnea_derivatives``), v and a: each (..., nv, nv)
    (qq [b, d] the slope along q_d of the gradient's entry b; qv, qa [d, e] = d2/dq_d dv_e, d2/dq_d da_e), the gradient
    (..., nv); aa and va are zero."""
def frame_velocity(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None, frame: _Frame = "local_world_aligned"
) -> np.ndarray:
    """Velocity [linear; angular] of the frame at `point` on `body` (Pinocchio's getFrameVelocity): (..., 6)."""
def frame_acceleration(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None,
    frame: _Frame = "local_world_aligned",
) -> np.ndarray:
    """Spatial acceleration [linear; angular] of the frame, gravity excluded (Pinocchio's getFrameAcceleration): (..., 6).
    The point's classical acceleration is the "local_world_aligned" linear part plus w x v."""
def frame_velocity_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None, frame: _Frame = "local_world_aligned"
) -> tuple[np.ndarray, np.ndarray]:
    """(dv/dq, dv/dv) of ``frame_velocity``, each (..., 6, nv), q on its tangent space (Pinocchio's
    getFrameVelocityDerivatives; in "local_world_aligned" Pinocchio holds the frame's origin still, and its dv/dq lacks
    w x J_lin in the linear rows)."""
def frame_acceleration_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, body: _Body, point: npt.ArrayLike | None = None,
    frame: _Frame = "local_world_aligned",
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(dv/dq, da/dq, da/dv, da/da) of ``frame_velocity`` and ``frame_acceleration``, each (..., 6, nv) (Pinocchio's
    getFrameAccelerationDerivatives; in "local_world_aligned" its da/dq also lacks alpha x J_lin)."""
def center_of_mass(model: Model, q: npt.ArrayLike) -> np.ndarray:
    """World centre of mass: (..., 3)."""
def subtree_mass_properties(model: Model, q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-body subtree (mass (..., nb), com (..., nb, 3), inertia about the subtree COM (..., nb, 3, 3)), world frame."""
def centroidal_momentum(model: Model, q: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray:
    """[h_lin, h_ang about the COM], world-aligned: (..., 6)."""
def centroidal_map(model: Model, q: npt.ArrayLike) -> np.ndarray:
    """The centroidal momentum matrix A_G, centroidal_momentum(q, v) = A_G(q) v: (..., 6, nv)."""
def centroidal_momentum_rate(model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike) -> np.ndarray:
    """Time derivative of the centroidal momentum (gravity excluded): (..., 6)."""
def kinetic_energy(model: Model, q: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray: ...
def potential_energy(model: Model, q: npt.ArrayLike) -> np.ndarray: ...
def contact_dynamics(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, tau: npt.ArrayLike, contacts: _ContactPoints, dim: Literal[3, 6] = 3
) -> tuple[np.ndarray, np.ndarray]:
    """(ddq (..., nv), forces (..., k, dim)) with each contact (body, point in body frame) held still: its point
    (dim=3) or its body's frame at the point (dim=6; the forces are then wrenches [force; torque about the point]),
    world axes. Dependent (redundant) contacts, whose forces are not unique, get the minimum-norm forces; a singular
    mass matrix raises RuntimeError."""
def impact(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, contacts: _ContactPoints, dim: Literal[3, 6] = 3
) -> tuple[np.ndarray, np.ndarray]:
    """(v_plus (..., nv), impulses (..., k, dim)) of a perfectly inelastic impact at the contacts (dim, dependent
    contacts and errors as ``contact_dynamics``)."""
def contact_dynamics_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, tau: npt.ArrayLike, contacts: _ContactPoints, dim: Literal[3, 6] = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ddq/dq, ddq/dv, ddq/dtau) each (..., nv, nv) and (forces/dq, forces/dv, forces/dtau) each (..., k, dim, nv) of
    ``contact_dynamics``, q on its tangent space (Pinocchio's computeConstraintDynamicsDerivatives, CONTACT_3D or, with
    dim=6, CONTACT_6D contacts in LOCAL_WORLD_ALIGNED). Dependent contacts raise ValueError naming the first contact
    that repeats what the others hold (the contact Gram matrix J M^-1 J^T is singular): their forces, and so the
    derivatives, are not unique."""
def impact_derivatives(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, contacts: _ContactPoints, dim: Literal[3, 6] = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(v_plus/dq, v_plus/dv) each (..., nv, nv) and (impulses/dq, impulses/dv) each (..., k, dim, nv) of ``impact``
    (Pinocchio's computeImpulseDynamicsDerivatives without restitution). Dependent contacts raise ValueError, as in
    ``contact_dynamics_derivatives``."""
def point_accelerations(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, contacts: _ContactPoints, dim: Literal[3, 6] = 3
) -> np.ndarray:
    """World-axes (classical) acceleration J ddq + dJ/dt dq of each (body, point in body frame): (..., k, 3); with
    dim=6, the frame's spatial acceleration [linear; angular] at the point, world axes: (..., k, 6). Zero for the
    contacts `contact_dynamics` holds (with the same dim), at its ddq."""
def reduced_dynamics(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, tau: npt.ArrayLike, contacts: _ContactPoints, independent: Sequence[int] | None = None
) -> tuple[np.ndarray, list[int], list[int], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ddq, independent, dependent, basis N, reduced mass N^T M N, reduced force, offset) for one state."""
def integrate(model: Model, q: npt.ArrayLike, v: npt.ArrayLike, dt: float = 1.0) -> np.ndarray:
    """q (+) v dt: (..., nq); dt = 1 is Pinocchio's integrate(model, q, v)."""
def difference(model: Model, q0: npt.ArrayLike, q1: npt.ArrayLike) -> np.ndarray:
    """q1 (-) q0, the velocity v with integrate(q0, v, 1) = q1, as Pinocchio's difference: (..., nv). A free-flyer base's
    part is the SE(3) log of q0's pose to q1's, [v_lin, w] in the base frame at q0, of angle <= pi; the other
    coordinates subtract."""
def integrate_jacobians(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, dt: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(d(q (+) v dt)/dq, d(q (+) v dt)/dv), each (..., nv, nv), block diagonal, on the tangent spaces (the input
    perturbed as q (+) dq, the output measured by ``difference`` from q (+) v dt): Pinocchio's dIntegrate(q, v dt) for
    ARG0 and dt times it for ARG1. A free-flyer base's blocks are Ad(exp(v dt))^-1 and dt J_r(v dt) (the right
    Jacobian of SE(3)'s exp); the other coordinates' are 1 and dt. Neither depends on q (checked as in
    ``integrate``)."""
def difference_jacobians(model: Model, q0: npt.ArrayLike, q1: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(d(q1 (-) q0)/dq0, d(q1 (-) q0)/dq1), each (..., nv, nv), block diagonal, on the tangent spaces: Pinocchio's
    dDifference for ARG0 and ARG1. A free-flyer base's blocks are -J_r(x)^-1 Ad(M0^-1 M1)^-1 and J_r(x)^-1 (Jlog6)
    at x = q1 (-) q0; the other coordinates' are -1 and 1. With q1 = q0 (+) v, d1 @ dv = I from
    ``integrate_jacobians(q0, v)`` while v's angle is below pi."""
def free_rollout(
    model: Model, q: npt.ArrayLike, v: npt.ArrayLike, dt: float, steps: int, tau: npt.ArrayLike | None = None,
    method: Literal["rk4", "semi_implicit_euler"] = "rk4",
) -> tuple[np.ndarray, np.ndarray]:
    """(qs (..., steps + 1, nq), vs (..., steps + 1, nv)) of the free dynamics (ABA: no contacts, no ground, no joint
    limits) rolled out from (q, v); contact simulation is ``Simulation``. tau: (nv,) or (steps, nv), anything else a
    ValueError. MemoryError (naming steps) if the outputs cannot be allocated; Ctrl-C interrupts a long rollout."""
def circle_line(
    center: npt.ArrayLike, normal: npt.ArrayLike, radius: npt.ArrayLike, line_point: npt.ArrayLike, line_direction: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
def rotation_toward_line(
    axis_point: npt.ArrayLike, axis_direction: npt.ArrayLike, point: npt.ArrayLike, line_point: npt.ArrayLike,
    line_direction: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray]: ...

_ShapeSpec = tuple[Any, ...] | None

class Ground:
    """Terrain for a Simulation: a plane (z = 0, or placed anywhere), or a heightfield centred on the origin."""
    @staticmethod
    def plane(friction: float = 0.8, placement: _Placement | None = None) -> Ground:
        """The plane z = 0, solid below; with ``placement`` (4x4 or (R, t), plane to world) the plane z = 0 of that
        frame, its normal the frame's z axis, as MuJoCo places a plane geom."""
    @staticmethod
    def heightfield(heights: npt.ArrayLike, cell_size: float, friction: float = 0.8) -> Ground:
        """heights (nx, ny), nx, ny >= 2: height at x = (i - (nx-1)/2) cell_size, y = (j - (ny-1)/2) cell_size."""
    @property
    def kind(self) -> Literal["plane", "heightfield"]: ...
    @property
    def friction(self) -> float: ...
    @property
    def heights(self) -> np.ndarray | None: ...
    @property
    def cell_size(self) -> float | None: ...
    @property
    def placement(self) -> np.ndarray | None:
        """A plane's frame in the world (4, 4) (the identity: z = 0); None for a heightfield."""

class Simulation:
    """Contact simulation of a Model: legkit's tree engine (backend="tree", default) or Rapier's multibody
    (backend="rapier", the reference). substeps and solver_iterations in 1..1000; shape sizes at most 1e6 m.
    friction_law (tree engine): "coulomb", Coulomb's law (the default: no lift off a sliding contact; not convex),
    or "cone", the convex relaxation |f_t| <= mu f_n (unique impulses; a sliding contact separates at
    v_n = mu |v_t|, so sliding bodies hop)."""
    def __init__(
        self, model: Model, dt: float = 1e-3, ground: Ground | None = None, shapes: dict[int | str, _ShapeSpec] | None = None,
        self_collision: bool = False, substeps: int = 1,
        backend: Literal["tree", "rapier"] = "tree", solver_iterations: int = 50,
        friction_law: Literal["cone", "coulomb"] = "coulomb",
    ) -> None: ...
    @property
    def friction_law(self) -> Literal["cone", "coulomb"]: ...
    @property
    def model(self) -> Model:
        """The Model simulated: a copy of the one it was built from, as it was then; changing it is a ValueError, and
        changing the Model it was built from changes neither the simulation nor this."""
    @property
    def backend(self) -> Literal["tree", "rapier"]: ...
    @property
    def last_solver_iterations(self) -> int | None:
        """Newton iterations of the contact solver in the last (sub)step (tree engine); None on Rapier."""
    def step(self, tau: npt.ArrayLike | None = None, n: int | None = None, targets: npt.ArrayLike | None = None) -> None:
        """n steps (default 1) with feed-forward tau (nv,) held over them; GIL released. RuntimeError (naming the
        step and the body) if the state would diverge, the simulation then exactly as before that step (state,
        time, contact history, applied_tau, contacts()). Ctrl-C interrupts between steps (KeyboardInterrupt),
        keeping the steps taken; RuntimeError if another thread is stepping the same Simulation.
        targets (n, nv): the servos' position targets per velocity coordinate, one row per step (base entries
        unused; n defaults to the rows and must match them if given), checked whole before any step; the
        servos keep the last row's targets. Bit-identical to set_servo(target_q=...) and step() per row."""
    def transition_jacobians(self, tau: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """A = dx+/dx (2nv, 2nv) and B = dx+/du (2nv, 3nv) of one step from the current state, x = (dq on q's
        tangent space, v), u = (tau, servo target_q per velocity coordinate, servo target_v); changes nothing.
        The step's contacts, their zones, saturated servos and active limits are held. Tree backend; a step of
        several substeps is their chain, the warm starts followed (docs/derivatives.md)."""
    @overload
    def rollout(self, controls: npt.ArrayLike, jacobians: Literal[False] = False) -> tuple[np.ndarray, np.ndarray]:
        """One step per row of controls (N, nv), each row that step's feed-forward tau, from the current state under the
        current servos, as MuJoCo's ``rollout`` (GIL released, Ctrl-C between steps): (q (N, nq), v (N, nv)), the state
        after each step; with jacobians=True also A (N, 2nv, 2nv) and B (N, 2nv, 3nv), each step's
        ``transition_jacobians`` at its start. The simulation advances exactly as N calls of step(controls[k]).
        ValueError for another shape, no rows or a non-finite value (nothing moves); a failing step raises
        RuntimeError at its last good state, the steps before it taken."""
    @overload
    def rollout(self, controls: npt.ArrayLike, jacobians: Literal[True]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    def set_servo(
        self, kp: npt.ArrayLike, kd: npt.ArrayLike | None = None, torque_limit: npt.ArrayLike | None = None,
        target_q: npt.ArrayLike | None = None, target_v: npt.ArrayLike | None = None,
    ) -> None:
        """tau = clip(kp (target_q - q) + kd (target_v - v) + tau_ff, +-min(torque_limit, effort limit)), every step."""
    @property
    def q(self) -> np.ndarray: ...
    @q.setter
    def q(self, value: npt.ArrayLike) -> None: ...
    @property
    def v(self) -> np.ndarray: ...
    @v.setter
    def v(self, value: npt.ArrayLike) -> None: ...
    @property
    def time(self) -> float: ...
    @property
    def dt(self) -> float: ...
    @property
    def applied_tau(self) -> np.ndarray: ...
    @property
    def contact_tolerance(self) -> float: ...
    def body_poses(self) -> np.ndarray:
        """(nbodies, 4, 4) world poses."""
    def contacts(self) -> dict[str, np.ndarray]:
        """body, other (-1: ground), point (k,3), normal (k,3) into body, normal_force (k,), tangential_force (k,3), depth (k,)."""
    def reset(self, q: npt.ArrayLike | None = None, v: npt.ArrayLike | None = None) -> None: ...

class SimulationBatch:
    """Steps many Simulations (any models, any backends) in parallel on all cores, GIL released."""
    def __init__(self, simulations: Sequence[Simulation]) -> None: ...
    def step(self, tau: npt.ArrayLike | Sequence[npt.ArrayLike | None] | None = None, n: int = 1) -> None:
        """tau: None, (nv,) for all, (B, nv), or a list with one (nv,) array (or None) per simulation. Per member: a
        simulation that diverges stops as before its failed step while the others take all n steps; then a
        RuntimeError names the lowest such index and which members stopped after how many steps, and its ``steps``
        attribute lists the steps each member took. Ctrl-C interrupts between steps, every simulation having
        taken the same whole steps."""
    def transition_jacobians(
        self, tau: npt.ArrayLike | Sequence[npt.ArrayLike | None] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Every simulation's (A, B) at its state, in parallel: (B, 2nv, 2nv) and (B, 2nv, 3nv) (one nv for all)."""
    @overload
    def rollout(self, controls: npt.ArrayLike, jacobians: Literal[False] = False) -> tuple[np.ndarray, np.ndarray]:
        """Every simulation's ``Simulation.rollout`` from its own state, in parallel on all cores: controls (B, N, nv),
        one sequence per simulation, or (N, nv) for all; (q (B, N, nq), v (B, N, nv)) and with jacobians=True
        A (B, N, 2nv, 2nv), B (B, N, 2nv, 3nv) (one nq and nv for all). A failing simulation stops at its last good
        state while the others complete; the error names the lowest index."""
    @overload
    def rollout(self, controls: npt.ArrayLike, jacobians: Literal[True]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    @property
    def simulations(self) -> list[Simulation]: ...
    @property
    def q(self) -> np.ndarray:
        """(B, nq), when all simulations share nq."""
    @property
    def v(self) -> np.ndarray:
        """(B, nv), when all simulations share nv."""
    def __len__(self) -> int: ...

class BalanceKernel:
    """Internal: the synchronous agent network and balancing controller in Rust; built and driven by
    ``legkit.control.BalanceKernel``, which documents it."""
    def __init__(
        self, partner_link: Sequence[int], mate: npt.ArrayLike, part_moments: npt.ArrayLike, connector_rotation: npt.ArrayLike,
        connector_position: npt.ArrayLike, joint_axes: Sequence[int], joint_z: Sequence[float], ground_module: Sequence[int],
        ground_block: Sequence[int], ground_pose: npt.ArrayLike, ground_line: npt.ArrayLike, ground_priority: Sequence[float],
        angles: npt.ArrayLike, scheme: Sequence[int], gains: npt.ArrayLike, limit: float, width: float,
    ) -> None: ...
    def run_until_quiescent(self, max_rounds: int) -> int: ...
    def step(self, angles: npt.ArrayLike, dt: float, rounds: int) -> np.ndarray: ...
    @property
    def sent_by_module(self) -> np.ndarray: ...
    def estimates(self) -> np.ndarray: ...
    def world_poses(self) -> tuple[np.ndarray, np.ndarray]: ...
