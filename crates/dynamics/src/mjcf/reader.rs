//! Reading an element's attributes through its default class (numbers, flags, frames and orientations in the
//! compiler's angle unit), and accepting what legkit does not model with a warning, or refusing it under `strict`.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, Quaternion, Unit, UnitQuaternion, Vector3};

use super::compiler::Compiler;
use super::defaults::{kind_of, Class};
use super::element::{numbers, El};
use super::invalid;
use crate::{Result, Transform};

/// Reads attributes with defaults, and warns or refuses.
pub(super) struct Reader<'a> {
    pub(super) classes: HashMap<String, Class>,
    pub(super) compiler: Compiler,
    pub(super) strict: bool,
    pub(super) warnings: Vec<String>,
    /// Warnings `strict` does not refuse (what legkit cannot read, e.g. a missing mesh file).
    pub(super) notes: Vec<String>,
    pub(super) folder: Option<&'a Path>,
}

impl Reader<'_> {
    pub(super) fn accept(&mut self, problem: String) -> Result<()> {
        if self.strict {
            return Err(invalid(format!("{problem} (strict)")));
        }
        self.warnings.push(problem);
        Ok(())
    }

    pub(super) fn class_of<'e>(&self, el: &'e El, childclass: &'e str) -> Result<&'e str> {
        let class = el.attr("class").unwrap_or(childclass);
        if !self.classes.contains_key(class) {
            return Err(invalid(format!("{}: unknown default class {class:?}", el.what())));
        }
        Ok(class)
    }

    pub(super) fn get<'e>(&'e self, el: &'e El, class: &str, key: &str) -> Option<&'e str> {
        el.attr(key).or_else(|| self.classes.get(class)?.get(kind_of(&el.tag))?.get(key).map(String::as_str))
    }

    pub(super) fn nums(&self, el: &El, class: &str, key: &str) -> Result<Option<Vec<f64>>> {
        self.get(el, class, key).map(|text| numbers(text, &|| format!("{}: {key}", el.what()))).transpose()
    }

    pub(super) fn fixed<const N: usize>(&self, el: &El, class: &str, key: &str) -> Result<Option<[f64; N]>> {
        match self.nums(el, class, key)? {
            None => Ok(None),
            Some(v) if v.len() == N => Ok(Some(v.try_into().expect("length checked"))),
            Some(v) => Err(invalid(format!("{}: {key} needs {N} numbers, found {}", el.what(), v.len()))),
        }
    }

    pub(super) fn scalar(&self, el: &El, class: &str, key: &str, default: f64) -> Result<f64> {
        Ok(self.fixed::<1>(el, class, key)?.map_or(default, |[x]| x))
    }

    pub(super) fn boolean(&self, el: &El, class: &str, key: &str) -> Result<Option<bool>> {
        match self.get(el, class, key) {
            None | Some("auto") => Ok(None),
            Some("true") => Ok(Some(true)),
            Some("false") => Ok(Some(false)),
            Some(other) => Err(invalid(format!("{}: {key}={other:?} must be true, false or auto", el.what()))),
        }
    }

    /// The element's frame in its parent's: `pos` and one orientation form.
    pub(super) fn frame(&self, el: &El, class: &str) -> Result<Transform> {
        let pos = self.fixed::<3>(el, class, "pos")?.map_or_else(Vector3::zeros, Vector3::from);
        Ok(Transform::new(self.orientation(el, class)?, pos))
    }

    fn orientation(&self, el: &El, class: &str) -> Result<Matrix3<f64>> {
        let forms = ["quat", "axisangle", "euler", "xyaxes", "zaxis"];
        // An orientation on the element replaces one from its class.
        let given: Vec<&str> = forms.iter().copied().filter(|f| el.attr(f).is_some()).collect();
        let given = if given.is_empty() { forms.iter().copied().filter(|f| self.get(el, class, f).is_some()).collect() } else { given };
        let q = match given.as_slice() {
            [] => return Ok(Matrix3::identity()),
            [form] => self.rotation(el, class, form)?,
            _ => return Err(invalid(format!("{}: more than one orientation ({})", el.what(), given.join(", ")))),
        };
        Ok(q.to_rotation_matrix().into_inner())
    }

    fn rotation(&self, el: &El, class: &str, form: &str) -> Result<UnitQuaternion<f64>> {
        let zero = || invalid(format!("{}: {form} is degenerate", el.what()));
        Ok(match form {
            "quat" => {
                let [w, x, y, z] = self.fixed::<4>(el, class, form)?.expect("present");
                let q = Quaternion::new(w, x, y, z);
                if q.norm() < 1e-10 {
                    return Err(zero());
                }
                UnitQuaternion::from_quaternion(q)
            }
            "axisangle" => {
                let [x, y, z, a] = self.fixed::<4>(el, class, form)?.expect("present");
                let axis = Unit::try_new(Vector3::new(x, y, z), 1e-10).ok_or_else(zero)?;
                UnitQuaternion::from_axis_angle(&axis, a * self.compiler.angle)
            }
            "euler" => self.euler(self.fixed::<3>(el, class, form)?.expect("present")),
            "xyaxes" => {
                let v = self.fixed::<6>(el, class, form)?.expect("present");
                let x = Vector3::new(v[0], v[1], v[2]);
                let x = x.try_normalize(1e-10).ok_or_else(zero)?;
                let y = Vector3::new(v[3], v[4], v[5]);
                let y = (y - x * x.dot(&y)).try_normalize(1e-10).ok_or_else(zero)?;
                let m = Matrix3::from_columns(&[x, y, x.cross(&y)]);
                UnitQuaternion::from_matrix(&m)
            }
            _ => {
                let [x, y, z] = self.fixed::<3>(el, class, form)?.expect("present");
                z_to(Vector3::new(x, y, z)).ok_or_else(zero)?
            }
        })
    }

    /// The rotation of Euler angles `angles` (in the compiler's unit and sequence).
    pub(super) fn euler(&self, angles: [f64; 3]) -> UnitQuaternion<f64> {
        let mut q = UnitQuaternion::identity();
        for (&c, angle) in self.compiler.eulerseq.iter().zip(angles) {
            let axis = match c.to_ascii_lowercase() {
                b'x' => Vector3::x_axis(),
                b'y' => Vector3::y_axis(),
                _ => Vector3::z_axis(),
            };
            let turn = UnitQuaternion::from_axis_angle(&axis, angle * self.compiler.angle);
            // Lower case: about the rotating (intrinsic) axes; upper case: the fixed ones.
            q = if c.is_ascii_lowercase() { q * turn } else { turn * q };
        }
        q
    }
}

/// The shortest rotation taking z to `v` (MuJoCo's `mju_quatZ2Vec`: half a turn about x for -z).
pub(super) fn z_to(v: Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let v = v.try_normalize(1e-14)?;
    let axis = Vector3::z().cross(&v);
    let s = axis.norm();
    if s < 1e-15 {
        return Some(if v.z < 0.0 { UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI) } else { UnitQuaternion::identity() });
    }
    Some(UnitQuaternion::from_axis_angle(&Unit::new_unchecked(axis / s), s.atan2(v.z)))
}
