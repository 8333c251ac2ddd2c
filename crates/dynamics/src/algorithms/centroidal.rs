//! Centroidal momentum (Orin & Goswami): the robot's linear momentum and its angular momentum about the
//! centre of mass, in world-aligned axes, its time derivative, the centroidal momentum matrix A_G, and the centre of
//! mass's Jacobian (A_G's linear rows over the mass).

use nalgebra::{Matrix3xX, Matrix6xX, Vector3, Vector6};

use super::checks::{check_state, finite_result};
use super::com::world_com;
use super::kinematics::{base_centred_kinematics, body_motions};
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_force, linear, spatial, Force, Motion};
use crate::Result;

/// Body velocities, accelerations (without gravity) and poses; returns the spatial momentum and its rate
/// about the world origin in world coordinates, and the centre of mass.
fn world_momentum(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>) -> (Vector6<f64>, Vector6<f64>, Vector3<f64>) {
    let (mut momentum, mut rate) = (Vector6::zeros(), Vector6::zeros());
    body_motions(model, data, q, v, a, Motion::zeros());
    for i in 0..model.nbodies() {
        let o_parent = if i == 0 { crate::Transform::identity() } else { data.o_m_i[model.parent(i)] };
        data.o_m_i[i] = o_parent.compose(&data.li_m_i[i]);
        let inertia = model.inertia(i);
        let h = inertia.apply(&data.v[i]);
        momentum += data.o_m_i[i].act_force(&h);
        if a.is_some() {
            rate += data.o_m_i[i].act_force(&(inertia.apply(&data.a[i]) + cross_force(&data.v[i], &h)));
        }
    }
    (momentum, rate, world_com(model, data))
}

/// `[h_lin; h_ang]`: linear momentum and angular momentum about the COM, world-aligned.
///
/// # Examples
///
/// The centroidal momentum of a double pendulum (two 1 kg links 0.4 m long, hinged about y; built in the hidden lines)
/// is A_G q̇ (`centroidal_map`); its linear part is the mass times the COM's velocity J_c q̇ (`center_of_mass_jacobian`,
/// checked against central differences of `center_of_mass` along the motion), and its rate (`centroidal_momentum_rate`)
/// is its time derivative along (q̇, q̈).
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
/// let (q, v, a, h) = ([0.3, -0.5], DVector::from_vec(vec![1.0, 2.0]), DVector::from_vec(vec![-3.0, 0.5]), 1e-6);
/// let momentum = algorithms::centroidal_momentum(&model, &mut data, &q, v.as_slice())?;
/// assert!((momentum - algorithms::centroidal_map(&model, &mut data, &q)? * &v).norm() < 1e-12);
/// let com_velocity = algorithms::center_of_mass_jacobian(&model, &mut data, &q)? * &v;
/// assert!((momentum.fixed_rows::<3>(0) - 2.0 * com_velocity).norm() < 1e-12);
/// // The state a time h before and after, moving with (q̇, q̈).
/// let along = |h: f64| (vec![q[0] + h * v[0], q[1] + h * v[1]], &v + h * &a);
/// let ((q_after, v_after), (q_before, v_before)) = (along(h), along(-h));
/// let com_after = algorithms::center_of_mass(&model, &mut data, &q_after)?;
/// assert!(((com_after - algorithms::center_of_mass(&model, &mut data, &q_before)?) / (2.0 * h) - com_velocity).norm() < 1e-8);
/// let rate = algorithms::centroidal_momentum_rate(&model, &mut data, &q, v.as_slice(), a.as_slice())?;
/// let after = algorithms::centroidal_momentum(&model, &mut data, &q_after, v_after.as_slice())?;
/// let before = algorithms::centroidal_momentum(&model, &mut data, &q_before, v_before.as_slice())?;
/// assert!((rate - (after - before) / (2.0 * h)).norm() < 1e-7);
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn centroidal_momentum(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> Result<Vector6<f64>> {
    check_state(model, data, q, &[("v", v)])?;
    let (momentum, _, com) = world_momentum(model, data, q, v, None);
    // Shift the moment from the world origin to the COM: L_G = L_O − c × p.
    let h = spatial(linear(&momentum), angular(&momentum) - com.cross(&linear(&momentum)));
    finite_result(h.as_slice())?;
    Ok(h)
}

/// d/dt `[h_lin; h_ang]` for joint accelerations `a` (gravity excluded): the net external wrench about the
/// COM. Since ċ × p = ċ × m ċ = 0, the rate about the COM is L̇_O − c × ṗ.
pub fn centroidal_momentum_rate(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64]) -> Result<Vector6<f64>> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    let (_, rate, com) = world_momentum(model, data, q, v, Some(a));
    let rate = spatial(linear(&rate), angular(&rate) - com.cross(&linear(&rate)));
    finite_result(rate.as_slice())?;
    Ok(rate)
}

/// The centroidal momentum matrix A_G (6 x nv, `h = A_G(q) v`, rows as `centroidal_momentum`'s) in
/// `data.centroidal_map`. As CRBA (Table 6.2) in the centred frame: a joint moves its subtree as one rigid
/// body, so its column is the subtree's composite inertia times its motion subspace (eq. 6.17's F), whose
/// moment is then taken about the COM.
pub fn centroidal_map<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> Result<&'d Matrix6xX<f64>> {
    check_state(model, data, q, &[])?;
    centroidal_map_unchecked(model, data, q);
    finite_result(data.centroidal_map.as_slice())?;
    Ok(&data.centroidal_map)
}

/// [`centroidal_map`] without its checks, for the crate's inner loops.
pub(crate) fn centroidal_map_unchecked<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d Matrix6xX<f64> {
    let n = model.nbodies();
    base_centred_kinematics(model, data, q);
    for i in 0..n {
        data.composite[i] = data.centred_m_i[i].act_rigid_inertia(model.inertia(i));
    }
    for i in (1..n).rev() {
        let composite = data.composite[i];
        data.composite[model.parent(i)] += composite;
    }
    let whole = data.composite[0];
    let com = if whole.mass > 0.0 { whole.first_moment / whole.mass } else { Vector3::zeros() };
    let about_com = |f: Force| spatial(linear(&f), angular(&f) - com.cross(&linear(&f)));
    for i in 0..n {
        let k = model.idx_v(i);
        match model.joint(i).dofs() {
            Dofs::Free | Dofs::Ball => {
                for c in 0..model.joint(i).nv() {
                    let s = model.joint(i).subspace_column_in(&data.centred_m_i[i], c);
                    data.centroidal_map.set_column(k + c, &about_com(data.composite[i].apply(&s)));
                }
            }
            Dofs::Zero => {}
            Dofs::One(_) => {
                let s = model.joint(i).subspace_in(&data.centred_m_i[i]);
                data.centroidal_map.set_column(k, &about_com(data.composite[i].apply(&s)));
            }
        }
    }
    &data.centroidal_map
}

/// The centre of mass's Jacobian ∂c/∂q (3 x nv, world axes; q on its tangent space, as `integrate` steps it;
/// Pinocchio's `jacobianCenterOfMass`) in `data.com_jacobian`: the linear rows of the centroidal momentum matrix
/// over the mass, since the linear momentum is m ċ = A_G q̇ (zeros for a massless model).
pub fn center_of_mass_jacobian<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> Result<&'d Matrix3xX<f64>> {
    check_state(model, data, q, &[])?;
    centroidal_map_unchecked(model, data, q);
    let mass = data.composite[0].mass;
    let per_mass = if mass > 0.0 { 1.0 / mass } else { 0.0 };
    for (mut jacobian, map) in data.com_jacobian.column_iter_mut().zip(data.centroidal_map.column_iter()) {
        jacobian.copy_from(&(map.fixed_rows::<3>(0) * per_mass));
    }
    Ok(&data.com_jacobian)
}
