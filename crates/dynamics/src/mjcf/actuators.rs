//! `<actuator>`: motor, position, velocity and general actuators on hinge and slide joints, as gains, biases and
//! ranges; the others are warnings.

use super::element::El;
use super::reader::Reader;
use super::{invalid, Actuator, JointKind, MjcfJoint};
use crate::Result;

/// The actuators of every `<actuator>` section on the kept `joints`, in MuJoCo's order.
pub(super) fn actuators(root: &El, joints: &[MjcfJoint], reader: &mut Reader) -> Result<Vec<Actuator>> {
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    for section in root.elements("actuator") {
        for el in &section.children {
            let class = reader.class_of(el, "main")?.to_owned();
            let name = el.attr("name").map_or_else(|| format!("actuator{}", out.len() + skipped.len()), str::to_owned);
            let Some(target) = reader.get(el, &class, "joint") else {
                skipped.push(format!("{} (not a joint transmission)", el.what()));
                continue;
            };
            let Some(joint) = joints.iter().find(|j| j.name == target) else {
                return Err(invalid(format!("{}: unknown joint {target:?}", el.what())));
            };
            if matches!(joint.kind, JointKind::Free | JointKind::Ball) {
                skipped.push(format!("{} (on a {} joint)", el.what(), if joint.kind == JointKind::Free { "free" } else { "ball" }));
                continue;
            }
            let gear = reader.nums(el, &class, "gear")?.map_or(1.0, |g| g.first().copied().unwrap_or(1.0));
            let kp = reader.scalar(el, &class, "kp", 1.0)?;
            let kv = reader.scalar(el, &class, "kv", if el.tag == "velocity" { 1.0 } else { 0.0 })?;
            let params = |key: &str| -> Result<[f64; 3]> {
                let mut p = [0.0; 3];
                if let Some(v) = reader.nums(el, &class, key)? {
                    for (slot, x) in p.iter_mut().zip(v) {
                        *slot = x;
                    }
                }
                Ok(p)
            };
            let (gain, bias) = match el.tag.as_str() {
                "motor" => ([1.0, 0.0, 0.0], [0.0; 3]),
                "position" => {
                    if reader.scalar(el, &class, "timeconst", 0.0)? != 0.0 || reader.get(el, &class, "dampratio").is_some() {
                        skipped.push(format!("{} (timeconst or dampratio)", el.what()));
                        continue;
                    }
                    ([kp, 0.0, 0.0], [0.0, -kp, -kv])
                }
                "velocity" => ([kv, 0.0, 0.0], [0.0, 0.0, -kv]),
                "general" => {
                    let dyn_ok = reader.get(el, &class, "dyntype").is_none_or(|d| d == "none");
                    let gain_type = reader.get(el, &class, "gaintype").unwrap_or("fixed");
                    let bias_type = reader.get(el, &class, "biastype").unwrap_or("none");
                    if !dyn_ok || !matches!(gain_type, "fixed" | "affine") || !matches!(bias_type, "none" | "affine") {
                        skipped.push(format!("{} (dyntype, gaintype or biastype)", el.what()));
                        continue;
                    }
                    let mut gain = params("gainprm")?;
                    if reader.nums(el, &class, "gainprm")?.is_none() {
                        gain[0] = 1.0;
                    }
                    if gain_type == "fixed" {
                        gain[1] = 0.0;
                        gain[2] = 0.0;
                    }
                    let bias = if bias_type == "none" { [0.0; 3] } else { params("biasprm")? };
                    (gain, bias)
                }
                _ => {
                    skipped.push(format!("{} (kind)", el.what()));
                    continue;
                }
            };
            let range = |key: &str, limited: &str| -> Result<Option<[f64; 2]>> {
                let r = reader.fixed::<2>(el, &class, key)?;
                let on = reader.boolean(el, &class, limited)?.unwrap_or(reader.compiler.autolimits && r.is_some());
                Ok(if on { Some(r.unwrap_or([0.0, 0.0])) } else { None })
            };
            let ctrlrange = range("ctrlrange", "ctrllimited")?;
            let forcerange = range("forcerange", "forcelimited")?;
            out.push(Actuator { name, joint: target.to_owned(), dof: joint.idx_v, gear, gain, bias, ctrlrange, forcerange });
        }
    }
    if !skipped.is_empty() {
        reader.accept(format!("actuators not supported: {}", skipped.join(", ")))?;
    }
    Ok(out)
}
