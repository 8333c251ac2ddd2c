//! Building the [`Model`]: the world or the free body as the base, MuJoCo's bodies in order, each multi-joint body
//! a chain, hinge frames at their anchors, damping, armature and collision shapes per coordinate and body.

use nalgebra::{Matrix3, Vector3};

use super::body::Body;
use super::joint::JointSpec;
use super::reader::Reader;
use super::{invalid, JointKind, MjcfJoint, MjcfOptions};
use crate::geometry::Shape;
use crate::mesh::cancel_point;
use crate::{Error, Joint, JointLimits, MassProperties, Model, Result, Transform};

/// The model: the world (or the free body) as the base, then MuJoCo's bodies in order.
pub(super) fn build(bodies: &[Body], options: &MjcfOptions, reader: &mut Reader) -> Result<(Model, Vec<MjcfJoint>)> {
    let top: Vec<usize> = (1..bodies.len()).filter(|&b| bodies[b].parent == 0).collect();
    for body in &bodies[1..] {
        let free = body.joints.iter().filter(|j| j.kind == JointKind::Free).count();
        if free > 0 && (body.parent != 0 || body.joints.len() > 1) {
            return Err(invalid(format!("body {:?}: a free joint must be the only joint of a top-level body", body.name)));
        }
    }
    let has_free = |b: usize| bodies[b].joints.iter().any(|j| j.kind == JointKind::Free);
    let moving: Vec<usize> = top.iter().copied().filter(|&b| !bodies[b].joints.is_empty()).collect();
    let free: Vec<usize> = top.iter().copied().filter(|&b| has_free(b)).collect();
    let names = |list: &[usize]| list.iter().map(|&b| format!("{:?}", bodies[b].name)).collect::<Vec<_>>().join(", ");
    // Several free bodies (a robot and a ball): a fixed world, each free body on three slides along the world's
    // axes and a ball joint, which are MuJoCo's free-joint coordinates (position, and linear velocity, in the world
    // frame; orientation, and angular velocity, in the body's).
    let free_chains = options.floating_base.is_none() && free.len() > 1;
    let floating = options.floating_base.unwrap_or(free.len() == 1);
    let base_body = if floating {
        let candidates = if moving.is_empty() { top.clone() } else { moving.clone() };
        match candidates.as_slice() {
            [b] if bodies[*b].joints.iter().all(|j| j.kind == JointKind::Free) => Some(*b),
            [b] => return Err(invalid(format!("body {:?}: a floating base cannot also have hinge or slide joints", bodies[*b].name))),
            [] => return Err(invalid("no body to make the floating base".into())),
            _ => return Err(invalid(format!("a floating base needs a single moving top-level body; found {}", names(&candidates)))),
        }
    } else {
        None
    };
    let mut model;
    let mut kept = vec![false; bodies.len()];
    // The legkit body of each MJCF body, and the anchor offset of its frame.
    let mut legkit = vec![(0usize, Vector3::zeros()); bodies.len()];
    let mut joints = Vec::new();
    let mut damping = Vec::new();
    let mut armature = Vec::new();
    if let Some(b) = base_body {
        let body = &bodies[b];
        model = Model::new(true, body.mass, &body.name);
        kept[b] = true;
        let spec = &body.joints[0];
        joints.push(MjcfJoint { name: spec.name.clone(), kind: JointKind::Free, body: 0, idx_q: 0, idx_v: 0 });
        model.set_joint_name(0, &spec.name);
        // legkit's free-flyer coordinates carry no armature or damping (Pinocchio's neither).
        for (key, value) in [("damping", spec.damping), ("armature", spec.armature)] {
            if value != 0.0 {
                reader.accept(format!("free joint {:?}: {key}={value} is not modelled on a floating base", spec.name))?;
            }
        }
        let dropped: Vec<usize> = top.iter().copied().filter(|&t| t != b).collect();
        if !dropped.is_empty() {
            reader.accept(format!("static top-level bodies {} are left out of the floating-base model", names(&dropped)))?;
        }
        if let Some(shapes) = Some(&bodies[0].shapes).filter(|s| !s.is_empty()) {
            reader.notes.push(format!("the world's {} collision geoms are left out of the floating-base model (use lk.Ground)", shapes.len()));
        }
    } else {
        model = Model::new(false, MassProperties::zero(), "world");
        kept[0] = true;
    }
    let mut shapes: Vec<(usize, Shape)> = Vec::new();
    let shifted = |shape: &Shape, shift: &Vector3<f64>| -> Shape {
        let mut s = shape.clone();
        let p = s.placement.unwrap_or_default();
        s.placement = Some(Transform::from_translation(-shift).compose(&p));
        s
    };
    if base_body.is_none() {
        shapes.extend(bodies[0].shapes.iter().map(|s| (0, s.clone())));
    } else if let Some(b) = base_body {
        shapes.extend(bodies[b].shapes.iter().map(|s| (0, s.clone())));
    }
    for (b, body) in bodies.iter().enumerate().skip(1) {
        cancel_point("from_mjcf", b)?;
        if kept[b] || !kept[body.parent] {
            continue;
        }
        kept[b] = true;
        let (mut parent, parent_shift) = legkit[body.parent];
        let mut frame = Transform::from_translation(-parent_shift).compose(&body.frame);
        let mut anchor = Vector3::zeros();
        let free_welded = body.joints.iter().any(|j| j.kind == JointKind::Free);
        let moving: Vec<&JointSpec> = if free_welded { Vec::new() } else { body.joints.iter().collect() };
        let fail = |e: Error| invalid(format!("body {:?}: {e}", body.name));
        if free_welded && free_chains {
            let spec = &body.joints[0];
            let first = model.nbodies();
            for (k, axis) in ["x", "y", "z"].iter().zip([Vector3::x(), Vector3::y(), Vector3::z()]) {
                let name = format!("{}/{}:{k}", body.name, spec.name);
                parent = model
                    .add_body(parent, Joint::Prismatic(axis), Transform::identity(), MassProperties::zero(), &name, JointLimits::NONE)
                    .map_err(fail)?;
            }
            parent = model.add_body(parent, Joint::Spherical, Transform::identity(), body.mass, &body.name, JointLimits::NONE).map_err(fail)?;
            let (idx_q, idx_v) = (model.idx_q(first), model.idx_v(first));
            joints.push(MjcfJoint { name: spec.name.clone(), kind: JointKind::Free, body: parent, idx_q, idx_v });
            // Its four legkit joints: the first under its name (where its coordinates start), the others suffixed.
            for (i, suffix) in (first..=parent).zip(["", ":y", ":z", ":rotation"]) {
                model.set_joint_name(i, &format!("{}{suffix}", spec.name));
            }
            for k in idx_v..idx_v + 6 {
                damping.push((k, spec.damping));
                armature.push((k, spec.armature));
            }
            legkit[b] = (parent, anchor);
            shapes.extend(body.shapes.iter().map(|s| (parent, s.clone())));
            continue;
        }
        for (k, spec) in moving.iter().enumerate() {
            let last = k + 1 == moving.len();
            let name = if last { body.name.clone() } else { format!("{}/{}", body.name, spec.name) };
            let (joint, placement) = match spec.kind {
                JointKind::Hinge => {
                    let placement = frame.compose(&Transform::from_translation(spec.pos - anchor)).rotated_about(&spec.axis, -spec.reference);
                    anchor = spec.pos;
                    (Joint::Revolute(spec.axis), placement)
                }
                // Turns about its anchor, as a hinge: q is MuJoCo's qpos with w last.
                JointKind::Ball => {
                    let placement = frame.compose(&Transform::from_translation(spec.pos - anchor));
                    anchor = spec.pos;
                    (Joint::Spherical, placement)
                }
                _ => (Joint::Prismatic(spec.axis), frame.compose(&Transform::from_translation(-spec.axis * spec.reference))),
            };
            let limits = match spec.range {
                Some((lo, hi)) => JointLimits::new(lo, hi, f64::INFINITY, f64::INFINITY).map_err(fail)?,
                None => JointLimits::NONE,
            };
            let mass = if last { body.mass.transformed_unchecked(&Matrix3::identity(), &-anchor) } else { MassProperties::zero() };
            parent = model.add_body(parent, joint, placement, mass, &name, limits).map_err(fail)?;
            let kind = spec.kind;
            joints.push(MjcfJoint { name: spec.name.clone(), kind, body: parent, idx_q: model.idx_q(parent), idx_v: model.idx_v(parent) });
            model.set_joint_name(parent, &spec.name);
            for k in model.idx_v(parent)..model.idx_v(parent) + model.joint(parent).nv() {
                damping.push((k, spec.damping));
                armature.push((k, spec.armature));
            }
            frame = Transform::identity();
        }
        if moving.is_empty() {
            parent = model.add_body(parent, Joint::Fixed, frame, body.mass, &body.name, JointLimits::NONE).map_err(fail)?;
        }
        legkit[b] = (parent, anchor);
        shapes.extend(body.shapes.iter().map(|s| (parent, shifted(s, &anchor))));
    }
    let set = |values: &[(usize, f64)], n: usize| -> Vec<f64> {
        let mut out = vec![0.0; n];
        for &(k, x) in values {
            out[k] = x;
        }
        out
    };
    model.set_damping(&set(&damping, model.nv()))?;
    model.set_armature(&set(&armature, model.nv()))?;
    if !shapes.is_empty() {
        model.set_collision_shapes(shapes)?;
    }
    Ok((model, joints))
}
