//! `<joint>` and `<freejoint>`: a joint's kind, anchor, axis, reference, range, damping and armature, in its
//! body's frame.

use nalgebra::Vector3;

use super::element::El;
use super::reader::Reader;
use super::{invalid, JointKind};
use crate::{Result, Transform};

/// A joint as the file gives it, in its body's MJCF frame.
pub(super) struct JointSpec {
    pub(super) name: String,
    pub(super) kind: JointKind,
    pub(super) pos: Vector3<f64>,
    pub(super) axis: Vector3<f64>,
    pub(super) reference: f64,
    pub(super) range: Option<(f64, f64)>,
    pub(super) damping: f64,
    pub(super) armature: f64,
}

pub(super) fn joint(el: &El, class: &str, prefix: &Transform, reader: &mut Reader, id: usize) -> Result<JointSpec> {
    let name = el.attr("name").map_or_else(|| format!("joint{id}"), str::to_owned);
    if el.tag == "freejoint" {
        // MuJoCo's <freejoint> takes no joint defaults: no damping, armature or stiffness.
        return Ok(JointSpec {
            name,
            kind: JointKind::Free,
            pos: Vector3::zeros(),
            axis: Vector3::z(),
            reference: 0.0,
            range: None,
            damping: 0.0,
            armature: 0.0,
        });
    }
    let kind = reader.get(el, class, "type").unwrap_or("hinge");
    let kind = match kind {
        "hinge" => JointKind::Hinge,
        "slide" => JointKind::Slide,
        "free" => JointKind::Free,
        "ball" => JointKind::Ball,
        other => return Err(invalid(format!("joint {name:?} ({}): unknown type {other:?}", el.at))),
    };
    let pos = prefix.transform_point(&reader.fixed::<3>(el, class, "pos")?.map_or_else(Vector3::zeros, Vector3::from));
    let axis = prefix.rotation * reader.fixed::<3>(el, class, "axis")?.map_or_else(Vector3::z, Vector3::from);
    let axis = axis.try_normalize(1e-10).ok_or_else(|| invalid(format!("joint {name:?}: zero axis")))?;
    let scale = if matches!(kind, JointKind::Hinge | JointKind::Ball) { reader.compiler.angle } else { 1.0 };
    let range = reader.fixed::<2>(el, class, "range")?;
    let limited = match reader.boolean(el, class, "limited")? {
        Some(b) => b,
        None => reader.compiler.autolimits && range.is_some(),
    };
    let range = match (kind, limited, range) {
        (JointKind::Free, _, _) | (_, false, _) => None,
        // A ball joint's range bounds its rotation angle (MuJoCo's cone), which JointLimits cannot express.
        (JointKind::Ball, true, r) => {
            reader.accept(format!("joint {name:?}: the range {r:?} of a ball joint is not modelled"))?;
            None
        }
        (_, true, r) => {
            let [lo, hi] = r.unwrap_or([0.0, 0.0]);
            if lo > hi {
                return Err(invalid(format!("joint {name:?}: range {lo} > {hi}")));
            }
            Some((lo * scale, hi * scale))
        }
    };
    // MuJoCo reads `ref` on hinges and slides only: a ball joint's qpos0 is the identity.
    let reference = if matches!(kind, JointKind::Hinge | JointKind::Slide) { reader.scalar(el, class, "ref", 0.0)? * scale } else { 0.0 };
    let damping = reader.scalar(el, class, "damping", 0.0)?;
    let armature = reader.scalar(el, class, "armature", 0.0)?;
    if damping < 0.0 || armature < 0.0 {
        return Err(invalid(format!("joint {name:?}: damping and armature must be >= 0")));
    }
    for key in ["stiffness", "frictionloss"] {
        let value = reader.scalar(el, class, key, 0.0)?;
        if value != 0.0 {
            reader.accept(format!("joint {name:?}: {key}={value} is not modelled"))?;
        }
    }
    // MuJoCo derives a stiffness and a damping from the joint's effective mass in place of `damping`.
    if let Some(value @ [timeconst, _]) = reader.fixed::<2>(el, class, "springdamper")? {
        if timeconst > 0.0 {
            reader.accept(format!("joint {name:?}: springdamper={value:?} is not modelled (its damping={damping} applies)"))?;
        }
    }
    Ok(JointSpec { name, kind, pos, axis, reference, range, damping, armature })
}
