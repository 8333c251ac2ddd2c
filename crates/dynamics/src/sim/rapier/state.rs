//! Reading and writing the simulation state in legkit's conventions: q = [base pose (x, y, z, qx, qy,
//! qz, qw) if floating, joint coordinates], v = [base (v_lin, ω) in the base frame if floating, joint
//! velocities], body poses in the world, and contact forces.
//!
//! Rapier's multibody keeps the free root's velocity as [velocity of its centre of mass, ω], both in the
//! world frame, and a revolute (prismatic) joint's coordinate as its angular (linear) x coordinate.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rapier3d_f64::math::{Pose, Vector};
use rapier3d_f64::prelude::{Multibody, PhysicsWorld};

use super::builder::{Layout, RapierAxis, GROUND_TAG};
use crate::geometry::{from_pose, from_vector, to_pose, to_vector};
use crate::model::Model;
use crate::sim::Contact;
use crate::spatial::Transform;

pub(crate) fn multibody<'w>(world: &'w PhysicsWorld, layout: &Layout) -> Option<&'w Multibody> {
    layout.joint_handle.map(|h| world.multibody_joints.get(h).expect("joint handle is valid").0)
}

/// World pose of Rapier body `r` (its Rapier frame).
pub(crate) fn carrier_pose(world: &PhysicsWorld, layout: &Layout, r: usize) -> Pose {
    match (multibody(world, layout), &layout.links) {
        (Some(mb), Some(links)) => *mb.link(links[r]).expect("link exists").local_to_world(),
        _ => *world.bodies[layout.handles[r]].position(),
    }
}

/// World pose of every legkit body.
pub(crate) fn body_poses(world: &PhysicsWorld, layout: &Layout) -> Vec<Transform> {
    let carriers: Vec<Transform> = (0..layout.handles.len()).map(|r| from_pose(&carrier_pose(world, layout, r))).collect();
    layout.carrier.iter().zip(&layout.offset).map(|(&r, o)| carriers[r].compose(o)).collect()
}

/// The base's [velocity of the Rapier root's frame origin (its centre of mass), ω], world frame.
fn root_velocity(world: &PhysicsWorld, layout: &Layout) -> (Vector3<f64>, Vector3<f64>) {
    match multibody(world, layout) {
        Some(mb) => {
            let g = mb.generalized_velocity();
            (Vector3::new(g[0], g[1], g[2]), Vector3::new(g[3], g[4], g[5]))
        }
        None => {
            let rb = &world.bodies[layout.handles[0]];
            (from_vector(rb.linvel()), from_vector(rb.angvel()))
        }
    }
}

/// The legkit configuration and velocity.
pub(crate) fn read(world: &PhysicsWorld, layout: &Layout, model: &Model, q: &mut [f64], v: &mut [f64]) {
    if model.floating_base() {
        let root = from_pose(&carrier_pose(world, layout, 0));
        let base = root.compose(&layout.offset[0]);
        let rotation = UnitQuaternion::from_matrix(&base.rotation);
        let sign = if rotation.w < 0.0 { -1.0 } else { 1.0 };
        q[..3].copy_from_slice(base.translation.as_slice());
        q[3..7].copy_from_slice(&[sign * rotation.i, sign * rotation.j, sign * rotation.k, sign * rotation.w]);
        let (v_com, w) = root_velocity(world, layout);
        // Velocity of the base origin: v_o = v_c + ω × (o − c), then both into the base frame.
        let com = root.transform_point(&layout.local_com[0]);
        let v_origin = v_com + w.cross(&(base.translation - com));
        let rt = base.rotation.transpose();
        v[..3].copy_from_slice((rt * v_origin).as_slice());
        v[3..6].copy_from_slice((rt * w).as_slice());
    }
    let (Some(mb), Some(links)) = (multibody(world, layout), &layout.links) else { return };
    let g = mb.generalized_velocity();
    for i in 1..model.nbodies() {
        let Some(axis) = RapierAxis::of(model.joint(i)) else { continue };
        let coordinate = axis.coordinate();
        let link = mb.link(links[layout.carrier[i]]).expect("link exists");
        q[model.idx_q(i)] = link.joint().coords()[coordinate];
        v[model.idx_v(i)] = g[link.assembly_id()];
    }
}

/// Sets the configuration and velocity (both checked by the caller).
pub(crate) fn write(world: &mut PhysicsWorld, layout: &Layout, model: &Model, q: &[f64], v: &[f64]) {
    // Base pose and the velocity of the Rapier root (its centre of mass), world frame.
    let mut root_velocity = None;
    if model.floating_base() {
        let rotation = UnitQuaternion::from_quaternion(Quaternion::new(q[6], q[3], q[4], q[5]));
        let base = Transform::from_quaternion(Vector3::new(q[0], q[1], q[2]), &rotation);
        let root = base.compose(&layout.offset[0].inverse());
        let w = base.rotation * Vector3::new(v[3], v[4], v[5]);
        let com = root.transform_point(&layout.local_com[0]);
        let v_com = base.rotation * Vector3::new(v[0], v[1], v[2]) + w.cross(&(com - base.translation));
        let rb = &mut world.bodies[layout.handles[0]];
        rb.set_position(to_pose(&root), true);
        rb.set_linvel(to_vector(&v_com), true);
        rb.set_angvel(to_vector(&w), true);
        root_velocity = Some((v_com, w));
    }
    let (Some(handle), Some(links)) = (layout.joint_handle, &layout.links) else { return };
    let PhysicsWorld { multibody_joints, bodies, .. } = world;
    let (mb, _) = multibody_joints.get_mut(handle).expect("joint handle is valid");
    for i in 1..model.nbodies() {
        let Some(axis) = RapierAxis::of(model.joint(i)) else { continue };
        let joint = &mut mb.link_mut(links[layout.carrier[i]]).expect("link exists").joint;
        let coordinate = axis.coordinate();
        // x + (−x) is exactly 0 and 0 + q exactly q, so the coordinate is set bit for bit.
        joint.apply_displacement(&[-joint.coords()[coordinate]]);
        joint.apply_displacement(&[q[model.idx_q(i)]]);
    }
    mb.forward_kinematics(bodies, true);
    mb.update_rigid_bodies(bodies, true);
    let assembly: Vec<(usize, usize)> = (1..model.nbodies())
        .filter(|&i| RapierAxis::of(model.joint(i)).is_some())
        .map(|i| (mb.link(links[layout.carrier[i]]).expect("link exists").assembly_id(), model.idx_v(i)))
        .collect();
    let mut g = mb.generalized_velocity_mut();
    if let Some((v_com, w)) = root_velocity {
        for k in 0..3 {
            g[k] = v_com[k];
            g[k + 3] = w[k];
        }
    }
    for (a, k) in assembly {
        g[a] = v[k];
    }
}

/// Tangent basis of Rapier's friction constraints for a force direction `d` (Pixar's branchless
/// orthonormal basis, as in `rapier3d::utils::OrthonormalBasis`; second vector d × t1).
fn friction_basis(d: Vector) -> (Vector, Vector) {
    let sign = 1f64.copysign(d.z);
    let a = -1.0 / (sign + d.z);
    let b = d.x * d.y * a;
    let t1 = Vector::new(b, sign + d.y * d.y * a, -d.y);
    (t1, d.cross(t1))
}

/// Every active contact point of the last step. A body-body contact appears once, seen from the body of
/// the pair's first collider.
pub(crate) fn contacts(world: &PhysicsWorld, dt: f64) -> Vec<Contact> {
    let mut out = Vec::new();
    for pair in world.narrow_phase.contact_pairs() {
        let (Some(c1), Some(c2)) = (world.colliders.get(pair.collider1), world.colliders.get(pair.collider2)) else { continue };
        let (tag1, tag2) = (c1.user_data, c2.user_data);
        // Rapier's manifold normal points from collider 1 to collider 2; its impulse λ >= 0 pushes
        // collider 1 along −normal (and its friction impulse acts on collider 1 in the basis of −normal).
        let (body, other, flip) = if tag1 == GROUND_TAG { (tag2, None, -1.0) } else { (tag1, (tag2 != GROUND_TAG).then_some(tag2 as usize), 1.0) };
        for manifold in pair.solver_manifolds() {
            let n = manifold.data.normal;
            let (t1, t2) = friction_basis(-n);
            for solver_contact in &manifold.data.solver_contacts {
                let id = solver_contact.contact_indices()[0] as usize;
                let Some(point) = manifold.points.get(id) else { continue };
                let (p1, p2) = manifold.data.solver_contact_world_points(solver_contact, &world.bodies);
                let friction = t1 * point.data.tangent_impulse.x + t2 * point.data.tangent_impulse.y;
                out.push(Contact {
                    body: body as usize,
                    other,
                    point: from_vector((p1 + p2) * 0.5),
                    normal: from_vector(n * -flip),
                    normal_force: point.data.impulse / dt,
                    tangential_force: from_vector(friction * (flip / dt)),
                    depth: (-point.dist).max(0.0),
                });
            }
        }
    }
    out
}
