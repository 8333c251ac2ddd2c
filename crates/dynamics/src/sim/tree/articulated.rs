//! Products with, and solves against, the contact solver's Newton matrix on the tree, in O(n):
//!   H = M̃ + Σ_b Φ_bᵀ K_b Φ_b + diag(c),
//! with Φ_b the map from joint velocities to body b's spatial velocity, K_b a 6x6 stiffness on body b and
//! c a stiffness on each joint coordinate (armature and c act on one- and three-degree-of-freedom joints; a
//! free-flyer base has neither, as in `aba_with_armature`). M̃ = Σ_b Φ_bᵀ I_b Φ_b + diag(armature) is linear in the bodies'
//! inertias, so H is the mass matrix of the same tree with inertias I_b + K_b and armatures + c, and the
//! articulated-body recursion without velocities (Featherstone, Table 7.1) factors and solves it with no
//! fill-in; a ball joint's pivot D is a 3x3 block [Featherstone 2008, eq. 7.43]. Everything is in the world's axes about the base origin, as `aba` leaves `Data`.

use nalgebra::{Cholesky, Matrix3, Matrix6, Matrix6x3, Vector3, LU, U6};

use crate::algorithms::aba::{ball_factors, ball_subspace};
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{add_reduced_inertia, dot6, Force, Motion};

pub(super) struct Articulated {
    /// Each body's stiffness K_b while H is assembled (the caller adds it), to which `factor` adds the
    /// children's articulated inertias and reads the body's own as I_b + this; zero between assemblies (the
    /// factor clears what it reads), so assembling copies no body's constant inertia. Per one-degree-of-freedom joint U = I^A S, its left
    /// counterpart (I^A)ᵀ S and D⁻¹ (eq. 7.38–7.44). K_b may be unsymmetric (a sliding contact's friction
    /// bound following its normal impulse, `solver`): the recursion is Gaussian elimination on the tree, and
    /// needs only nonzero pivots D, U on the right and (I^A)ᵀ S on the left.
    pub stiffness: Vec<Matrix6<f64>>,
    u: Vec<Motion>,
    u_left: Vec<Motion>,
    d_inv: Vec<f64>,
    /// The same per ball joint, by body (after `factor` or `factor_of_aba` alike).
    ball: Vec<BallFactor>,
    base: Option<Base>,
    /// `solve` uses the factor ABA left in `Data` (`factor_of_aba`) rather than `u` and `d_inv`.
    of_aba: bool,
    /// u_k = r_k − S_kᵀ p_k of the last solve's backward pass, per velocity coordinate.
    reduced: Vec<f64>,
    /// c per coordinate: set by the caller before `factor`.
    pub coordinate_stiffness: Vec<f64>,
    /// Body spatial velocities of the last `motions`; body forces for `generalized`.
    pub motion: Vec<Motion>,
    pub force: Vec<Force>,
}

/// A ball joint's S, U = I^A S, (I^A)ᵀ S and D⁻¹ (3x3).
#[derive(Debug, Clone, Copy, Default)]
struct BallFactor {
    s: Matrix6x3<f64>,
    u: Matrix6x3<f64>,
    u_left: Matrix6x3<f64>,
    d_inv: Matrix3<f64>,
}

/// A free-flyer base's factored block D_0 = I^A_0: Cholesky while H is symmetric, LU otherwise.
enum Base {
    Cholesky(Cholesky<f64, U6>),
    Lu(LU<f64, U6, U6>),
}

impl Articulated {
    pub(super) fn new(model: &Model) -> Self {
        let (n, nv) = (model.nbodies(), model.nv());
        Articulated {
            stiffness: vec![Matrix6::zeros(); n],
            u: vec![Motion::zeros(); n],
            u_left: vec![Motion::zeros(); n],
            d_inv: vec![0.0; n],
            ball: vec![BallFactor::default(); n],
            base: None,
            of_aba: false,
            reduced: vec![0.0; nv],
            coordinate_stiffness: vec![0.0; nv],
            motion: vec![Motion::zeros(); n],
            force: vec![Force::zeros(); n],
        }
    }

    /// Each body's spatial velocity Φ_b x, into `motion`.
    pub(super) fn motions(&mut self, model: &Model, data: &Data, x: &[f64]) {
        for i in 0..model.nbodies() {
            let k = model.idx_v(i);
            self.motion[i] = match model.joint(i).dofs() {
                Dofs::Free => data.centred_m_i[i].act_motion(&Motion::from_column_slice(&x[k..k + 6])),
                Dofs::Zero if i == 0 => Motion::zeros(),
                Dofs::Zero => self.motion[model.parent(i)],
                Dofs::One(_) => self.motion[model.parent(i)] + data.s[i] * x[k],
                Dofs::Ball => self.motion[model.parent(i)] + ball_subspace(&data.centred_m_i[i]) * Vector3::from_column_slice(&x[k..k + 3]),
            };
        }
    }

    /// out = Σ_b Φ_bᵀ f_b for the body forces in `force` (which it accumulates into subtree sums).
    pub(super) fn generalized(&mut self, model: &Model, data: &Data, out: &mut [f64]) {
        for i in (0..model.nbodies()).rev() {
            let k = model.idx_v(i);
            match model.joint(i).dofs() {
                Dofs::Free => out[k..k + 6].copy_from_slice(data.centred_m_i[i].inv_act_force(&self.force[i]).as_slice()),
                Dofs::Zero => {}
                Dofs::One(_) => out[k] = dot6(&data.s[i], self.force[i].as_slice()),
                Dofs::Ball => out[k..k + 3].copy_from_slice(ball_subspace(&data.centred_m_i[i]).tr_mul(&self.force[i]).as_slice()),
            }
            if i > 0 {
                let f = self.force[i];
                self.force[model.parent(i)] += f;
            }
        }
    }

    /// out = M̃ x.
    #[cfg(test)]
    pub(super) fn mass_times(&mut self, model: &Model, data: &Data, armature: &[f64], x: &[f64], out: &mut [f64]) {
        self.motions(model, data, x);
        self.mass_times_motions(model, data, armature, x, out);
    }

    /// out = M̃ x, with `motion` holding Φ_b x (from `motions`).
    pub(super) fn mass_times_motions(&mut self, model: &Model, data: &Data, armature: &[f64], x: &[f64], out: &mut [f64]) {
        for ((f, rigid), m) in self.force.iter_mut().zip(&data.rigid).zip(&self.motion) {
            *f = rigid * m;
        }
        self.generalized(model, data, out);
        for ((o, a), x) in out.iter_mut().zip(armature).zip(x) {
            *o += a * x;
        }
    }

    /// Starts assembling H: no coordinate stiffness (the bodies' is zero already, `stiffness`).
    pub(super) fn clear_stiffness(&mut self) {
        self.coordinate_stiffness.fill(0.0);
    }

    /// Factors H, assembled in `stiffness` and `coordinate_stiffness`, and clears `stiffness`; false if a pivot
    /// D is not positive (H is not positive definite) or, for an unsymmetric H (`definite` false), if one is
    /// nearly zero.
    pub(super) fn factor(&mut self, model: &Model, data: &Data, armature: &[f64], definite: bool) -> bool {
        self.of_aba = false;
        for i in (1..model.nbodies()).rev() {
            if !self.factor_joint(model, data, armature, definite, i) {
                self.stiffness[..i].fill(Matrix6::zeros());
                return false;
            }
        }
        let base = data.rigid[0] + std::mem::replace(&mut self.stiffness[0], Matrix6::zeros());
        self.factor_base(model, base, definite)
    }

    /// Body `i`'s step of `factor`: its joint's pivots from its articulated inertia, I_i + `stiffness[i]`
    /// (which it clears), and what passes to its parent; false if a pivot fails.
    fn factor_joint(&mut self, model: &Model, data: &Data, armature: &[f64], definite: bool, i: usize) -> bool {
        let k = model.idx_v(i);
        let articulated = data.rigid[i] + std::mem::replace(&mut self.stiffness[i], Matrix6::zeros());
        let parent = &mut self.stiffness[model.parent(i)];
        if model.joint(i).dofs() == Dofs::Ball {
            // The same with three columns (eq. 7.43): the parent gets I^A − U D⁻¹ ((I^A)ᵀ S)ᵀ.
            let s = ball_subspace(&data.centred_m_i[i]);
            let u = articulated * s;
            let u_left = if definite { u } else { articulated.tr_mul(&s) };
            let added = Vector3::from_fn(|r, _| armature[k + r] + self.coordinate_stiffness[k + r]);
            let d = s.tr_mul(&u) + Matrix3::from_diagonal(&added);
            let d_inv = if definite {
                d.cholesky().map(|c| c.inverse())
            } else {
                let lu = d.lu();
                let scale = u.norm() * s.norm() + added.amax();
                let pivots = lu.u().diagonal();
                (d.iter().all(|x| x.is_finite()) && pivots.iter().all(|p| p.abs() > 1e-9 * scale)).then(|| lu.try_inverse()).flatten()
            };
            let Some(d_inv) = d_inv else {
                return false;
            };
            *parent += articulated - u * d_inv * u_left.transpose();
            self.ball[i] = BallFactor { s, u, u_left, d_inv };
            return true;
        }
        let w = if model.joint(i).nv() == 1 {
            // eq. 7.39–7.40
            let u = articulated * data.s[i];
            // (I^A)ᵀ S is U itself while H is symmetric.
            let u_left = if definite { u } else { articulated.tr_mul(&data.s[i]) };
            let added = armature[k] + self.coordinate_stiffness[k];
            let d = dot6(&data.s[i], u.as_slice()) + added;
            // Unsymmetric, a pivot may be negative; one that cancels to rounding would amplify it.
            let pivot = if definite { d > 0.0 } else { d.is_finite() && d.abs() > 1e-9 * (u.norm() * data.s[i].norm() + added.abs()) };
            if !pivot {
                return false;
            }
            self.u[i] = u;
            self.u_left[i] = u_left;
            self.d_inv[i] = 1.0 / d;
            u_left / d
        } else {
            Motion::zeros()
        };
        add_reduced_inertia(parent, &articulated, &self.u[i], &w);
        true
    }

    /// Takes the factor of M̃ itself (no stiffness) from the one `aba_with_armature` left in `data` (with
    /// `armature`), with a free-flyer base's block factored as `base` (`Delassus::base`); false if that is missing.
    pub(super) fn factor_of_aba(&mut self, model: &Model, data: &Data, armature: &[f64], base: Option<&Cholesky<f64, U6>>) -> bool {
        self.of_aba = true;
        // ABA keeps no ball joint's factors, only its articulated inertia.
        for i in 1..model.nbodies() {
            if model.joint(i).dofs() == Dofs::Ball {
                let k = model.idx_v(i);
                let (s, u, d_inv) = ball_factors(&data.centred_m_i[i], &data.inertia[i], &armature[k..k + 3]);
                self.ball[i] = BallFactor { s, u, u_left: u, d_inv };
            }
        }
        self.base = base.filter(|_| model.floating_base()).cloned().map(Base::Cholesky);
        self.base.is_some() || !model.floating_base()
    }

    /// A free-flyer base's block D_0 = I^A_0 = C Cᵀ if `definite` (false if it is not positive definite), else
    /// by LU (false if it is singular or not finite).
    fn factor_base(&mut self, model: &Model, inertia: Matrix6<f64>, definite: bool) -> bool {
        self.base = match (model.floating_base(), definite) {
            (false, _) => return true,
            (true, true) => Cholesky::new(inertia).map(Base::Cholesky),
            (true, false) => {
                let lu = inertia.lu();
                (lu.is_invertible() && inertia.iter().all(|x| x.is_finite())).then_some(Base::Lu(lu))
            }
        };
        self.base.is_some()
    }

    /// out = H⁻¹ rhs, after `factor` or `factor_of_aba`.
    pub(super) fn solve(&mut self, model: &Model, data: &Data, rhs: &[f64], out: &mut [f64]) {
        let (u, u_left, d_inv) = if self.of_aba { (&data.u, &data.u, &data.d_inv) } else { (&self.u, &self.u_left, &self.d_inv) };
        self.force.iter_mut().for_each(|p| *p = Force::zeros());
        // Backward: the bias forces p^A of the generalized forces alone (eq. 7.41–7.44).
        for i in (1..model.nbodies()).rev() {
            let k = model.idx_v(i);
            let mut p = self.force[i];
            if model.joint(i).nv() == 1 {
                let reduced = rhs[k] - dot6(&data.s[i], p.as_slice());
                p += u[i] * (reduced * d_inv[i]);
                self.reduced[k] = reduced;
            } else if model.joint(i).dofs() == Dofs::Ball {
                let b = &self.ball[i];
                let reduced = Vector3::from_column_slice(&rhs[k..k + 3]) - b.s.tr_mul(&p);
                p += b.u * (b.d_inv * reduced);
                self.reduced[k..k + 3].copy_from_slice(reduced.as_slice());
            }
            self.force[model.parent(i)] += p;
        }
        // Forward: accelerations from the root (eq. 7.45–7.47).
        self.motion[0] = match &self.base {
            Some(c) => {
                let pose = data.centred_m_i[0];
                let b = pose.act_force(&Force::from_column_slice(&rhs[0..6])) - self.force[0];
                let a = match c {
                    Base::Cholesky(c) => c.solve(&b),
                    Base::Lu(lu) => lu.solve(&b).unwrap_or_else(Motion::zeros),
                };
                out[0..6].copy_from_slice(pose.inv_act_motion(&a).as_slice());
                a
            }
            _ => Motion::zeros(),
        };
        for i in 1..model.nbodies() {
            let (k, parent) = (model.idx_v(i), self.motion[model.parent(i)]);
            self.motion[i] = if model.joint(i).nv() == 1 {
                let x = (self.reduced[k] - dot6(&u_left[i], parent.as_slice())) * d_inv[i];
                out[k] = x;
                parent + data.s[i] * x
            } else if model.joint(i).dofs() == Dofs::Ball {
                let b = &self.ball[i];
                let x = b.d_inv * (Vector3::from_column_slice(&self.reduced[k..k + 3]) - b.u_left.tr_mul(&parent));
                out[k..k + 3].copy_from_slice(x.as_slice());
                parent + b.s * x
            } else {
                parent
            };
        }
    }
}
