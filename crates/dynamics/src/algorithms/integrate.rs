//! Free dynamics (no contacts, no ground) integrated over the articulated-body algorithm: semi-implicit Euler
//! and RK4. `free_rollout` is the trajectory of it; contact simulation is `sim::Simulation`.

use nalgebra::DVector;

use super::checks::{check_output, check_state, finite_result, singular, singular_factor};
use super::{aba_unchecked, integrate_unchecked};
use crate::model::{Data, Model};
use crate::{Error, Result};

/// How [`Integrator`] and [`free_rollout`] step the free dynamics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// v ← v + h q̈(q, v); q ← q ⊕ h v: first order, symplectic for separable systems.
    SemiImplicitEuler,
    /// Classical fourth-order Runge–Kutta, stages combined in the tangent space.
    Rk4,
}

/// Buffers for stepping one model (allocated once).
pub struct Integrator {
    method: Method,
    q_stage: Vec<f64>,
    v_stage: DVector<f64>,
    v_sum: DVector<f64>,
    a_sum: DVector<f64>,
    q_next: Vec<f64>,
}

impl Integrator {
    /// Buffers sized for `model`, stepping with `method`.
    pub fn new(model: &Model, method: Method) -> Self {
        let nv = model.nv();
        Self {
            method,
            q_stage: vec![0.0; model.nq()],
            v_stage: DVector::zeros(nv),
            v_sum: DVector::zeros(nv),
            a_sum: DVector::zeros(nv),
            q_next: vec![0.0; model.nq()],
        }
    }

    /// Advances (q, v) by `dt` under joint forces `tau`.
    pub fn step(&mut self, model: &Model, data: &mut Data, q: &mut [f64], v: &mut DVector<f64>, tau: &[f64], dt: f64) {
        match self.method {
            Method::SemiImplicitEuler => {
                let acceleration = aba_unchecked(model, data, q, v.as_slice(), tau, None);
                v.axpy(dt, acceleration, 1.0);
                integrate_unchecked(model, q, v.as_slice(), dt, &mut self.q_next);
            }
            Method::Rk4 => {
                // Stage s evaluates q̈ at (q ⊕ c_s h v_{s−1}, v + c_s h a_{s−1}); weights 1, 2, 2, 1.
                self.v_sum.fill(0.0);
                self.a_sum.fill(0.0);
                self.q_stage.copy_from_slice(q);
                self.v_stage.copy_from(v);
                for (fraction, weight) in [(0.5, 1.0), (0.5, 2.0), (1.0, 2.0), (0.0, 1.0)] {
                    let acceleration = aba_unchecked(model, data, &self.q_stage, self.v_stage.as_slice(), tau, None);
                    self.v_sum.axpy(weight, &self.v_stage, 1.0);
                    self.a_sum.axpy(weight, acceleration, 1.0);
                    if fraction > 0.0 {
                        integrate_unchecked(model, q, self.v_stage.as_slice(), fraction * dt, &mut self.q_stage);
                        self.v_stage.copy_from(v);
                        self.v_stage.axpy(fraction * dt, &data.ddq, 1.0);
                    }
                }
                integrate_unchecked(model, q, self.v_sum.as_slice(), dt / 6.0, &mut self.q_next);
                v.axpy(dt / 6.0, &self.a_sum, 1.0);
            }
        }
        q.copy_from_slice(&self.q_next);
    }
}

/// Rolls the free dynamics (ABA, no contacts, no joint limits) out for `steps` steps from (q, v), with `tau`
/// constant (nv numbers) or per step (steps x nv). Writes (steps + 1) x nq configurations to `qs` and (steps + 1) x nv
/// velocities to `vs`, row by row. "Rollout" as in MuJoCo's `rollout`; "free" to keep it apart from the contact
/// `sim::Simulation`. Errors: `data` of another model, `q`, `v`, `tau`, `dt`, `qs` or `vs` invalid; `Error::Numerical`
/// if the state stops being finite: a singular mass matrix (told apart by the factor at the last finite state) or an
/// overflow.
///
/// # Examples
///
/// RK4 keeps a swinging double pendulum's energy (two 1 kg links 0.4 m long, hinged about y; built in the hidden lines)
/// to a part in a million over a second of 1 ms steps; an `Integrator` takes the same steps one at a time.
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
/// use legkit_dynamics::algorithms::{Integrator, Method};
/// let (q0, v0, steps, dt) = ([1.0, -0.5], [0.0, 2.0], 1000, 1e-3);
/// let (mut qs, mut vs) = (vec![0.0; 2 * (steps + 1)], vec![0.0; 2 * (steps + 1)]);
/// algorithms::free_rollout(&model, &mut data, &q0, &v0, &[0.0; 2], dt, steps, Method::Rk4, &mut qs, &mut vs)?;
/// let mut energy = |q: &[f64], v: &[f64]| -> legkit_dynamics::Result<f64> {
///     Ok(algorithms::kinetic_energy(&model, &mut data, q, v)? + algorithms::potential_energy(&model, &mut data, q)?)
/// };
/// let (start, end) = (energy(&q0, &v0)?, energy(&qs[2 * steps..], &vs[2 * steps..])?);
/// assert!((end - start).abs() < 1e-6 * start.abs());
///
/// let (mut q, mut v) = (q0, DVector::from_row_slice(&v0));
/// let mut integrator = Integrator::new(&model, Method::Rk4);
/// (0..steps).for_each(|_| integrator.step(&model, &mut data, &mut q, &mut v, &[0.0; 2], dt));
/// assert!(q == qs[2 * steps..] && v.as_slice() == &vs[2 * steps..]);
/// let error = algorithms::free_rollout(&model, &mut data, &q0, &v0, &[0.0; 2], dt, steps, Method::Rk4, &mut qs[1..], &mut vs).unwrap_err();
/// assert_eq!(error.to_string(), "qs: expected 2002 numbers, got 2001");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn free_rollout(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], dt: f64, steps: usize, method: Method, qs: &mut [f64], vs: &mut [f64],
) -> Result<()> {
    let (nq, nv) = (model.nq(), model.nv());
    check_state(model, data, q, &[("v", v)])?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(Error::invalid("dt", format!("must be finite and > 0, got {dt}")));
    }
    if tau.len() != nv && Some(tau.len()) != nv.checked_mul(steps) {
        return Err(Error::invalid("tau", format!("expected {nv} or steps x {nv} = {} numbers, got {}", nv.saturating_mul(steps), tau.len())));
    }
    if let Some(bad) = tau.iter().find(|x| !x.is_finite()) {
        return Err(Error::invalid("tau", format!("must be finite, got {bad}")));
    }
    let rows = steps.saturating_add(1);
    check_output("qs", qs, rows.saturating_mul(nq))?;
    check_output("vs", vs, rows.saturating_mul(nv))?;
    {
        // The states shadow (q, v) here only: the error below falls back on the initial ones.
        let mut integrator = Integrator::new(model, method);
        let mut q = q.to_vec();
        let mut v = DVector::from_column_slice(v);
        qs[..nq].copy_from_slice(&q);
        vs[..nv].copy_from_slice(v.as_slice());
        for s in 0..steps {
            let tau_s = if tau.len() == nv { tau } else { &tau[s * nv..(s + 1) * nv] };
            integrator.step(model, data, &mut q, &mut v, tau_s, dt);
            qs[(s + 1) * nq..(s + 2) * nq].copy_from_slice(&q);
            vs[(s + 1) * nv..(s + 2) * nv].copy_from_slice(v.as_slice());
        }
    }
    finite_result(qs).and_then(|()| finite_result(vs)).map_err(|overflow| {
        // The factor at the last finite state tells a singular mass matrix from an overflow.
        let finite = |x: &[f64]| x.iter().all(|x| x.is_finite());
        let last = qs.chunks_exact(nq.max(1)).zip(vs.chunks_exact(nv.max(1))).take_while(|(q, v)| finite(q) && finite(v)).last();
        let (q, v) = last.unwrap_or((q, v));
        let Some(tau) = tau.get(..nv) else { return overflow };
        aba_unchecked(model, data, q, v, tau, None);
        if singular_factor(model, data) {
            singular()
        } else {
            overflow
        }
    })
}
