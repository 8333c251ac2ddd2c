//! Each constraint's Delassus diagonal A_ii = J_i M̃⁻¹ J_iᵀ, which sets its regularisation, from the
//! factor `aba_with_armature` leaves in `Data`, in O(n) for all bodies plus O(1) per constraint.
//!
//! Ω_b = Φ_bᵀ M̃⁻¹ Φ_b is body b's apparent inverse inertia: its spatial acceleration under a unit spatial
//! force on it alone (Φ_b maps joint velocities to its spatial velocity). The articulated-body algorithm
//! passes a force on body i to its parent as P_iᵀ f and its parent's acceleration back as P_i a, with
//! P_i = 1 − S_i D_i⁻¹ U_iᵀ (Featherstone, Table 7.1, eq. 7.41–7.47, without velocities), so
//!   Ω_i = P_i Ω_λ(i) P_iᵀ + S_i D_i⁻¹ S_iᵀ,
//! from Ω_0 = 0 for a fixed base or (I^A_0)⁻¹ for a free-flyer. A force on body a with its opposite on b
//! couples the two through their nearest common ancestor c: Φ_aᵀ M̃⁻¹ Φ_b = T_a Ω_c T_bᵀ, with T_x the
//! product of the P's from c down to x. A unit generalized force on joint k of body i gives
//! (M̃⁻¹)_kk = D_i⁻¹ + w_iᵀ Ω_λ(i) w_i with w_i = U_i D_i⁻¹. A ball joint is the same with S_i and U_i 6x3 and
//! D_i 3x3 [Featherstone 2008, eq. 7.43]. Everything is in the world's axes about the base origin, as `aba`
//! leaves it in `Data`.

use nalgebra::{Cholesky, Matrix6, Matrix6x3, Vector3, Vector6, U6};

use crate::algorithms::aba::ball_factors;
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{dot6, Force};

pub(super) struct Delassus {
    /// Ω_b of each body.
    omega: Vec<Matrix6<f64>>,
    /// Each ball joint's S and W = U D⁻¹, by body (ABA keeps neither).
    ball: Vec<(Matrix6x3<f64>, Matrix6x3<f64>)>,
    /// A free-flyer base's articulated inertia I^A_0 = C Cᵀ, which the solver's first solve reuses.
    base: Option<Cholesky<f64, U6>>,
}

impl Delassus {
    pub(super) fn new(model: &Model) -> Self {
        let n = model.nbodies();
        Delassus { omega: vec![Matrix6::zeros(); n], ball: vec![(Matrix6x3::zeros(), Matrix6x3::zeros()); n], base: None }
    }

    /// Reads Ω of every body from the factor in `data` (of M + diag(`armature`)); false if a free-flyer base's
    /// articulated inertia is not positive definite.
    pub(super) fn update(&mut self, model: &Model, data: &Data, armature: &[f64]) -> bool {
        self.base = None;
        self.omega[0] = if model.floating_base() {
            match data.inertia[0].cholesky() {
                Some(c) => inverse_from_cholesky(self.base.insert(c).l_dirty()),
                None => return false,
            }
        } else {
            Matrix6::zeros()
        };
        for i in 1..model.nbodies() {
            // Written in place from the parent's (a parent precedes its children): no 6x6 copies.
            let (head, tail) = self.omega.split_at_mut(i);
            let (parent, omega) = (&head[model.parent(i)], &mut tail[0]);
            if model.joint(i).nv() == 1 {
                // P Ω Pᵀ + S D⁻¹ Sᵀ with P = 1 − S wᵀ: Ω + S zᵀ − y Sᵀ, y = Ω w, z = (wᵀ y + D⁻¹) S − y.
                let (s, w) = (data.s[i], data.u[i] * data.d_inv[i]);
                let y = parent * w;
                let z = s * (w.dot(&y) + data.d_inv[i]) - y;
                let (s, y, z) = (&s.data.0[0], &y.data.0[0], &z.data.0[0]);
                for (((column, from), z_c), s_c) in omega.data.0.iter_mut().zip(&parent.data.0).zip(z).zip(s) {
                    *column = std::array::from_fn(|r| from[r] + (s[r] * z_c - y[r] * s_c));
                }
            } else if model.joint(i).dofs() == Dofs::Ball {
                // The same with three columns: Ω + Z Sᵀ − S Yᵀ, Y = Ω W, Z = S (Wᵀ Y + D⁻¹) − Y.
                let k = model.idx_v(i);
                let (s, u, d_inv) = ball_factors(&data.centred_m_i[i], &data.inertia[i], &armature[k..k + 3]);
                let w = u * d_inv;
                let y = parent * w;
                let z = s * (w.tr_mul(&y) + d_inv) - y;
                *omega = parent + z * s.transpose() - s * y.transpose();
                self.ball[i] = (s, w);
            } else {
                *omega = *parent;
            }
        }
        true
    }

    /// The Cholesky factor of a free-flyer base's articulated inertia from the last `update` (None for a
    /// fixed base).
    pub(super) fn base(&self) -> Option<&Cholesky<f64, U6>> {
        self.base.as_ref()
    }

    /// A contact's Delassus diagonal, as [its normal row's, the sum of its two tangent rows'], and its scale
    /// (tr Ω |F|² per unit row), below which a row counts as immovable. `rows` are the forces [d; r × d] on
    /// body `a` (and opposite on `b`) of an orthonormal frame d = n, t1, t2 at arm `arm`.
    pub(super) fn contact(
        &self, model: &Model, data: &Data, a: usize, b: Option<usize>, rows: &[Vector6<f64>; 3], arm: &Vector3<f64>,
    ) -> ([f64; 2], f64) {
        let mut diagonal = point(&self.omega[a], &rows[0], arm);
        let mut trace = self.omega[a].trace();
        if let Some(b) = b {
            // + F Ω_b F − 2 F T_a Ω_c T_bᵀ F: each force passed up its chain to the common ancestor c.
            let (mut on_a, mut on_b) = (*rows, *rows);
            let (mut x, mut y) = (a, b);
            while x != y {
                if x > y {
                    transmit(model, data, &self.ball, x, &mut on_a);
                    x = model.parent(x);
                } else {
                    transmit(model, data, &self.ball, y, &mut on_b);
                    y = model.parent(y);
                }
            }
            let coupling: [f64; 3] = std::array::from_fn(|r| on_a[r].dot(&(self.omega[x] * on_b[r])));
            let [normal, tangents] = point(&self.omega[b], &rows[0], arm);
            diagonal[0] += normal - 2.0 * coupling[0];
            diagonal[1] += tangents - 2.0 * (coupling[1] + coupling[2]);
            trace += self.omega[b].trace();
        }
        (diagonal, trace)
    }

    /// (M̃⁻¹)_kk for the coordinate of body `i`'s one-degree-of-freedom joint.
    pub(super) fn coordinate(&self, model: &Model, data: &Data, i: usize) -> f64 {
        let w = data.u[i] * data.d_inv[i];
        data.d_inv[i] + w.dot(&(self.omega[model.parent(i)] * w))
    }
}

/// A⁻¹ = L⁻ᵀ L⁻¹ from the lower triangle of A's Cholesky factor L (the rest of `l` is ignored): the triangle's
/// inverse by forward substitution, then its Gram matrix, written out for 6x6 (nalgebra's `inverse` solves
/// against the identity column by column, at several times the cost, for every step of a free-flyer).
fn inverse_from_cholesky(l: &Matrix6<f64>) -> Matrix6<f64> {
    let mut w = [[0.0; 6]; 6]; // w[i][j] = (L⁻¹)_ij, i ≥ j
    for j in 0..6 {
        w[j][j] = 1.0 / l[(j, j)];
        for i in j + 1..6 {
            let sum: f64 = (j..i).map(|k| l[(i, k)] * w[k][j]).sum();
            w[i][j] = -sum / l[(i, i)];
        }
    }
    let mut inverse = Matrix6::zeros();
    for i in 0..6 {
        for j in 0..=i {
            let entry: f64 = (i..6).map(|k| w[k][i] * w[k][j]).sum();
            inverse[(i, j)] = entry;
            inverse[(j, i)] = entry;
        }
    }
    inverse
}

/// [fᵀ Ω f for the normal row f = [n; r × n], the same summed over the two tangent rows]. The three rows are
/// P d for the frame's directions d, with P = [1; [r]×], so the sum over all three is tr(Pᵀ Ω P) =
/// tr Ω_ll + 2 tr(Ω_la [r]×) + |r|² tr Ω_aa − rᵀ Ω_aa r (Ω symmetric): the tangents' sum without their rows.
fn point(omega: &Matrix6<f64>, normal_row: &Vector6<f64>, r: &Vector3<f64>) -> [f64; 2] {
    let o = omega;
    let normal = quadratic(o, normal_row);
    let linear = o[(0, 0)] + o[(1, 1)] + o[(2, 2)];
    let coupling = r.z * (o[(0, 4)] - o[(1, 3)]) + r.y * (o[(2, 3)] - o[(0, 5)]) + r.x * (o[(1, 5)] - o[(2, 4)]);
    let angular = o.fixed_view::<3, 3>(3, 3);
    let arm = r.norm_squared() * angular.trace() - r.dot(&(angular * r));
    [normal, linear + 2.0 * coupling + arm - normal]
}

/// fᵀ Ω f, as f · (Ω f) over Ω's columns (which vectorises, where the symmetric half would not).
fn quadratic(omega: &Matrix6<f64>, f: &Vector6<f64>) -> f64 {
    let (o, f) = (&omega.data.0, &f.data.0[0]);
    let mut product = [0.0; 6];
    for (column, f_c) in o.iter().zip(f) {
        for (p, o_rc) in product.iter_mut().zip(column) {
            *p += o_rc * f_c;
        }
    }
    product.iter().zip(f).map(|(p, f)| p * f).sum()
}

/// Forces on body `i` passed to its parent: f ← P_iᵀ f = f − w_i (S_iᵀ f).
fn transmit(model: &Model, data: &Data, ball: &[(Matrix6x3<f64>, Matrix6x3<f64>)], i: usize, forces: &mut [Force; 3]) {
    if model.joint(i).nv() == 1 {
        for f in forces.iter_mut() {
            let through = dot6(&data.s[i], f.as_slice()) * data.d_inv[i];
            *f -= data.u[i] * through;
        }
    } else if model.joint(i).dofs() == Dofs::Ball {
        let (s, w) = &ball[i];
        for f in forces.iter_mut() {
            *f -= w * s.tr_mul(f);
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Matrix6;

    use super::inverse_from_cholesky;

    #[test]
    fn the_inverse_from_the_cholesky_factor_inverts() {
        // A symmetric positive definite 6x6 of spread scales, as an articulated inertia (kg, kg m, kg m²).
        let b = Matrix6::from_fn(|r, c| ((r * 7 + c * 3) % 11) as f64 / 11.0 - 0.4);
        let a = b * b.transpose() + Matrix6::from_diagonal(&nalgebra::Vector6::new(3.0, 3.0, 3.0, 0.02, 0.03, 0.05));
        let inverse = inverse_from_cholesky(a.cholesky().expect("positive definite").l_dirty());
        let error = (a * inverse - Matrix6::identity()).abs().max();
        assert!(error < 1e-12, "A A⁻¹ − 1 off by {error}");
        assert_eq!(inverse, inverse.transpose());
    }
}
