//! Jacobians of frames attached to bodies, in Pinocchio's three conventions.

use nalgebra::{Matrix6xX, Vector3};

use super::checks::{check_frame, check_state, finite_result};
use super::forward_kinematics_unchecked;
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{angular, linear, spatial, Motion, Transform};
use crate::Result;

/// The frame a Jacobian's rows are expressed in (Pinocchio's `ReferenceFrame`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// The point's frame, axes along the body's.
    Local,
    /// The world frame: spatial velocity about the world origin.
    World,
    /// Velocity of the point itself, in world axes.
    LocalWorldAligned,
}

/// The 6 x nv Jacobian (rows `[linear; angular]`) of the frame at `point` (body coordinates) on `body`.
/// Runs forward kinematics; writes and returns `data.jacobian`.
///
/// # Examples
///
/// The tip of a double pendulum (links 0.4 m long, hinged about y, hanging along −z at q = 0; built in the hidden
/// lines), 0.8 m below the shoulder: in `Frame::LocalWorldAligned` (the point's own velocity, world axes) the shoulder
/// moves it along −x at 0.8 m/s per rad/s, the elbow at 0.4, and both turn it about y.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
/// # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
/// # let mut model = Model::new(false, MassProperties::zero(), "base");
/// # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
/// # let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
/// # model.add_body(1, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
/// # let mut data = Data::new(&model);
/// use legkit_dynamics::algorithms::Frame;
/// let tip = Vector3::new(0.0, 0.0, -0.4);
/// let j = algorithms::jacobian(&model, &mut data, &[0.0, 0.0], 2, &tip, Frame::LocalWorldAligned)?;
/// assert!((j.column(0) - Vector6::new(-0.8, 0.0, 0.0, 0.0, 1.0, 0.0)).norm() < 1e-12);
/// assert!((j.column(1) - Vector6::new(-0.4, 0.0, 0.0, 0.0, 1.0, 0.0)).norm() < 1e-12);
/// let error = algorithms::jacobian(&model, &mut data, &[0.0, 0.0], 3, &tip, Frame::World).unwrap_err();
/// assert_eq!(error.to_string(), "body: body 3 does not exist (the model has 3 bodies)");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn jacobian<'d>(model: &Model, data: &'d mut Data, q: &[f64], body: usize, point: &Vector3<f64>, frame: Frame) -> Result<&'d Matrix6xX<f64>> {
    check_state(model, data, q, &[])?;
    check_frame(model, body, point)?;
    jacobian_unchecked(model, data, q, body, point, frame);
    finite_result(data.jacobian.as_slice())?;
    Ok(&data.jacobian)
}

/// [`jacobian`] without its checks, for the crate's inner loops.
pub(crate) fn jacobian_unchecked<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], body: usize, point: &Vector3<f64>, frame: Frame,
) -> &'d Matrix6xX<f64> {
    forward_kinematics_unchecked(model, data, q);
    data.jacobian.fill(0.0);
    // Columns in the world frame (eq. 8.x of Featherstone: J = [⋯ ⁰Xⱼ Sⱼ ⋯] over the body's support).
    let mut j = body;
    loop {
        let k = model.idx_v(j);
        let pose = data.o_m_i[j];
        match model.joint(j).dofs() {
            Dofs::Free | Dofs::Ball => {
                for c in 0..model.joint(j).nv() {
                    data.jacobian.set_column(k + c, &model.joint(j).subspace_column_in(&pose, c));
                }
            }
            Dofs::Zero => {}
            Dofs::One(_) => data.jacobian.set_column(k, &model.joint(j).subspace_in(&pose)),
        }
        if j == 0 {
            break;
        }
        j = model.parent(j);
    }
    let origin = data.o_m_i[body].transform_point(point);
    match frame {
        Frame::World => {}
        Frame::LocalWorldAligned => {
            for mut column in data.jacobian.column_iter_mut() {
                let m = Motion::from(column.fixed_rows::<6>(0).into_owned());
                column.copy_from(&spatial(linear(&m) + angular(&m).cross(&origin), angular(&m)));
            }
        }
        Frame::Local => {
            let pose = Transform::new(data.o_m_i[body].rotation, origin);
            for mut column in data.jacobian.column_iter_mut() {
                let m = Motion::from(column.fixed_rows::<6>(0).into_owned());
                column.copy_from(&pose.inv_act_motion(&m));
            }
        }
    }
    &data.jacobian
}
