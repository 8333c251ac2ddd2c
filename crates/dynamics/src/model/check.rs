//! The argument checks of the public entry points (Pinocchio's `PINOCCHIO_CHECK_ARGUMENT_SIZE`): sizes,
//! finiteness, unit quaternions, and a [`Data`] used with the model that built it. Each names the argument.

use super::{Data, Model};
use crate::{Error, Result};

/// Checks a coordinate vector: length `n` and finite.
pub fn check_vector(argument: &'static str, x: &[f64], n: usize) -> Result<()> {
    if x.len() != n {
        return Err(Error::invalid(argument, format!("expected length {n}, got {}", x.len())));
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(argument, format!("element {i} is not finite ({})", x[i])));
    }
    Ok(())
}

impl Model {
    /// Checks a configuration: length `nq`, finite, and unit quaternions (to 1e-6): the base's and the ball joints'.
    pub fn check_configuration(&self, q: &[f64]) -> Result<()> {
        self.check_configuration_named("q", q)
    }

    /// `check_configuration` of the argument named `argument` (e.g. "q0").
    pub fn check_configuration_named(&self, argument: &'static str, q: &[f64]) -> Result<()> {
        check_vector(argument, q, self.nq)?;
        for (i, (joint, &k)) in self.joints.iter().zip(&self.idx_q).enumerate() {
            let Some(quaternion) = joint.quaternion_coordinates() else { continue };
            let (a, b) = (k + quaternion.start, k + quaternion.end);
            let norm = q[a..b].iter().map(|x| x * x).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-6 {
                let whose = if i == 0 { "the base quaternion".to_string() } else { format!("the quaternion of ball joint '{}'", self.names[i]) };
                return Err(Error::invalid(argument, format!("{whose} {argument}[{a}:{b}] must have unit norm, got {norm:.9}")));
            }
        }
        Ok(())
    }
}

/// Checks that `data` was built for `model` (`Data::new(&model)`, or a clone of either): a workspace sized for another
/// model would be read out of bounds or give another model's numbers. A model to which a body was added since is
/// another model.
pub fn check_data(model: &Model, data: &Data) -> Result<()> {
    if data.model != model.id() {
        return Err(Error::invalid("data", "was built for another model: make one with Data::new(&model) for this model"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Joint, JointLimits, MassProperties, Transform};
    use nalgebra::Vector3;

    #[test]
    fn data_belongs_to_its_model_and_its_clones_until_a_body_is_added() {
        let mut model = Model::new(false, MassProperties::zero(), "base");
        let data = Data::new(&model);
        assert!(check_data(&model, &data).is_ok());
        assert!(check_data(&model.clone(), &data.clone()).is_ok());
        let other = Model::new(false, MassProperties::zero(), "base");
        assert_eq!(check_data(&other, &data).unwrap_err().argument(), "data");
        model.add_body(0, Joint::Revolute(Vector3::z()), Transform::identity(), MassProperties::zero(), "link", JointLimits::NONE).unwrap();
        assert_eq!(check_data(&model, &data).unwrap_err().argument(), "data");
        assert!(check_data(&model, &Data::new(&model)).is_ok());
    }
}
