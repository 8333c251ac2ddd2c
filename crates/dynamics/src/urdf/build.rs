//! Building the [`Model`] from the links and joints read: the single root as the base, the bodies in Pinocchio's
//! depth-first order (children by joint name), `floating` joints as three slides and a ball, damping and
//! collision shapes per body.

use nalgebra::Vector3;

use super::read::{Link, UrdfJoint};
use super::{cancel_point, invalid, UrdfOptions};
use crate::validate::{filled, with_capacity};
use crate::{Error, Joint, JointLimits, MassProperties, Model, Result, Transform};

/// The model of `links` and `joints` (`parent_joint` the joint whose child each link is); `argument` is what a
/// size that cannot be allocated is reported against.
pub(super) fn model(
    links: &[Link], joints: &[UrdfJoint], parent_joint: &[Option<usize>], options: &UrdfOptions, argument: &'static str,
) -> Result<Model> {
    // The root, and Pinocchio's depth-first order from it.
    let roots: Vec<usize> = (0..links.len()).filter(|&l| parent_joint[l].is_none()).collect();
    let root = match roots.as_slice() {
        [root] => *root,
        [] => {
            return Err(invalid(format!(
                "no root link: every link is the child of a joint, so the joints form a cycle ({})",
                describe_cycle(links, joints, parent_joint, 0)
            )))
        }
        _ => {
            let names: Vec<String> = roots.iter().map(|&l| format!("{:?}", links[l].name)).collect();
            return Err(invalid(format!(
                "more than one root link (links that are no joint's child): {}; a URDF must be a single tree",
                names.join(", ")
            )));
        }
    };
    // Each link's child joints by name: `by_parent[first_child[l]..first_child[l + 1]]` (a counting sort,
    // in two tables rather than a vector per link, then each link's joints sorted).
    let mut first_child: Vec<usize> = filled(argument, links.len() + 1, 0)?;
    for joint in joints {
        first_child[joint.parent + 1] += 1;
    }
    for l in 0..links.len() {
        first_child[l + 1] += first_child[l];
    }
    let mut next: Vec<usize> = filled(argument, links.len(), 0)?;
    next.copy_from_slice(&first_child[..links.len()]);
    let mut by_parent: Vec<usize> = filled(argument, joints.len(), 0)?;
    for (j, joint) in joints.iter().enumerate() {
        by_parent[next[joint.parent]] = j;
        next[joint.parent] += 1;
    }
    for l in 0..links.len() {
        by_parent[first_child[l]..first_child[l + 1]].sort_unstable_by_key(|&j| joints[j].name);
    }

    if let Some(joint) = joints.iter().find(|j| options.floating_base && j.free && j.parent == root) {
        return Err(invalid(format!(
            "joint {:?}: a floating joint out of the root link {:?} with floating_base: the base would float twice (load with a fixed base)",
            joint.name, links[root].name
        )));
    }
    let mut model = Model::new(options.floating_base, links[root].body, links[root].name);
    let floating = joints.iter().filter(|j| j.free).count();
    model.try_reserve(argument, links.len() - 1 + 3 * floating, joints.iter().map(|j| j.joint.nv()).sum::<usize>() + 3 * floating)?;
    let mut body_of_link: Vec<Option<usize>> = filled(argument, links.len(), None)?;
    body_of_link[root] = Some(0);
    // Joints still to add, the next on top: a link's child joints go on in reverse name order, so that the
    // first comes off first, and its subtree before its siblings.
    let mut stack: Vec<usize> = with_capacity(argument, joints.len())?;
    stack.extend(by_parent[first_child[root]..first_child[root + 1]].iter().rev());
    while let Some(j) = stack.pop() {
        cancel_point(model.nbodies())?;
        let joint = &joints[j];
        let child = &links[joint.child];
        let fail = |e: Error| invalid(format!("joint {:?}: {e}", joint.name));
        let (mut parent, mut placement) = (body_of_link[joint.parent].expect("a joint is added after its parent link"), joint.placement);
        if joint.free {
            for (k, axis) in ["x", "y", "z"].iter().zip([Vector3::x(), Vector3::y(), Vector3::z()]) {
                let name = format!("{}/{}:{k}", child.name, joint.name);
                parent = model.add_body(parent, Joint::Prismatic(axis), placement, MassProperties::zero(), &name, JointLimits::NONE).map_err(fail)?;
                placement = Transform::identity();
            }
        }
        let body = model.add_body(parent, joint.joint, placement, child.body, child.name, joint.limits).map_err(fail)?;
        model.set_joint_name(body, joint.name);
        body_of_link[joint.child] = Some(body);
        stack.extend(by_parent[first_child[joint.child]..first_child[joint.child + 1]].iter().rev());
    }
    // With one parent per link and a single root, a link not reached from the root lies on a cycle.
    if let Some(unreached) = body_of_link.iter().position(Option::is_none) {
        return Err(invalid(format!("the joints form a cycle ({}), which is not a tree", describe_cycle(links, joints, parent_joint, unreached))));
    }
    let mut damping = model.damping().to_vec();
    for joint in joints.iter().filter(|j| j.joint.nv() > 0) {
        // A `floating` joint's three slides sit just before its ball, and take its damping too (MuJoCo damps
        // every coordinate of a free or ball joint by its one damping).
        let (slides, end) =
            (if joint.free { 3 } else { 0 }, model.idx_v(body_of_link[joint.child].expect("every link has a body")) + joint.joint.nv());
        damping[end - joint.joint.nv() - slides..end].fill(joint.damping);
    }
    model.set_damping(&damping)?;
    if links.iter().any(|link| !link.shapes.is_empty()) {
        let shapes = links.iter().zip(&body_of_link).flat_map(|(link, body)| {
            let body = body.expect("every link has a body");
            link.shapes.iter().map(move |shape| (body, shape.clone()))
        });
        model.set_collision_shapes(shapes.collect())?;
    }
    Ok(model)
}

/// Follows parent joints from link `start` until a link repeats; describes that cycle.
fn describe_cycle(links: &[Link], joints: &[UrdfJoint], parent_joint: &[Option<usize>], start: usize) -> String {
    let mut path = vec![start];
    let mut link = start;
    while let Some(j) = parent_joint[link] {
        link = joints[j].parent;
        if let Some(first) = path.iter().position(|&l| l == link) {
            // Listed parent -> child: the walk went child -> parent.
            let mut cycle: Vec<String> = path[first..].iter().map(|&l| format!("{:?}", links[l].name)).collect();
            cycle.push(format!("{:?}", links[link].name));
            cycle.reverse();
            return format!("parent -> child: {}", cycle.join(" -> "));
        }
        path.push(link);
    }
    // Unreachable for the callers (every link on the walk has a parent), kept total for safety.
    format!("through link {:?}", links[start].name)
}
