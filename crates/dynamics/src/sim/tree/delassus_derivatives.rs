//! The slopes of the constraints' Delassus diagonals (`delassus`) by the configuration, at fixed rows. For a row
//! j = (Φ_a − Φ_b)ᵀ f of a force f on body a (and −f on b; a unit generalized force for a joint limit), with
//! x = M̃⁻¹ j and the bodies' motions V_i = Φ_i x under it,
//!   ∂(jᵀ M̃⁻¹ j)/∂q_k = 2 f · ∂(V_a − V_b)/∂q_k − xᵀ (∂M/∂q_k) x.
//! Coordinate k of body i's joint moves i's subtree along S_k (its column of Φ_i, a right perturbation for a ball
//! joint or a free-flyer), carrying the subtree's axes and inertias with it: there ∂V_b/∂q_k = S_k × (V_b − V_λ(i))
//! (eq. 2.31's derivative of a moving motion, λ(i) the parent), and with İ = S ×* I − I S× the kinetic energy
//! T = ½ Σ_b V_bᵀ I_b V_b gives xᵀ (∂M/∂q_k) x = 2 ∂T/∂q_k with
//!   ∂T/∂q_k = −h_i · (S_k × V_λ(i)),   h_i = Σ_{b in i's subtree} I_b V_b (the subtree's momentum),
//! so one solve and three passes over the tree give a row's slopes by every coordinate, where differencing its
//! diagonal costs a factor per coordinate. Both terms are bilinear in the row: with x^m the solves of a basis β_m of
//! forces on the row's pair of bodies, a row Σ c_m β_m has slopes cᵀ D_k c, so a pair of bodies in three contacts or
//! more (nine rows or more) takes six solves in the unit basis where a solve per row would take one per row. Everything is in the world's axes about the base origin, as `aba` leaves
//! `Data`: a free-flyer's translation moves none of it, its rotation turns the whole tree (V_λ = 0, so T is unchanged).
//! The rows' own change with the configuration, a contact the coordinate moves, is the caller's:
//! 2 (∂f/∂q_k) · (V_a − V_b).

use nalgebra::{Cholesky, DMatrix, Matrix6, U6};

use super::articulated::Articulated;
use super::constraint::{Constraint, Target};
use crate::algorithms::aba::ball_subspace;
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{cross_motion, Force, Motion};
use crate::validate::{array_len, filled};
use crate::Result;

/// Buffers grown once per model.
#[derive(Default)]
pub(super) struct DiagonalSlopes {
    /// Rows 2c and 2c + 1: ∂/∂q of constraint c's diagonal [normal row's, summed over the tangent rows'] at fixed rows.
    pub slopes: DMatrix<f64>,
    /// Per constraint on bodies, V_a − V_b under each of its rows' x (n, t1, t2): what a change of that row dots with.
    pub motions: Vec<[Motion; 3]>,
    rhs: Vec<f64>,
    x: Vec<f64>,
    /// The constraints on bodies, ordered by their bodies: a group's rows are forces on the same pair.
    order: Vec<usize>,
    /// A group's basis of forces on its pair (its rows, or the six unit forces where it has more), and per basis
    /// force the bodies' motions V^m under its x^m and the subtrees' momenta.
    basis: Vec<Force>,
    responses: Vec<Vec<Motion>>,
    momenta: Vec<Vec<Force>>,
    /// Per coordinate k, D_k: a row of coefficients c in the basis has slope cᵀ D_k c.
    forms: Vec<Matrix6<f64>>,
}

impl DiagonalSlopes {
    /// The slopes of `constraints`' diagonals on the factor of M̃ = M + diag(`armature`) that `aba_with_armature` left in
    /// `data` (a free-flyer's block factored as `base`, `Delassus::base`), with `tree`'s buffers; false if that is missing.
    /// The diagonal is quadratic in the row, so its slopes are quadratic forms in the row's coefficients in any basis of
    /// forces on the pair: six solves serve a pair of bodies in many contacts, where a solve per row would be many.
    pub(super) fn compute(
        &mut self, model: &Model, data: &Data, armature: &[f64], base: Option<&Cholesky<f64, U6>>, tree: &mut Articulated, constraints: &[Constraint],
    ) -> Result<bool> {
        let (nv, n) = (model.nv(), model.nbodies());
        if !tree.factor_of_aba(model, data, armature, base) {
            return Ok(false);
        }
        if self.slopes.shape() != (2 * constraints.len(), nv) {
            let len = array_len("model", &[2 * constraints.len(), nv], std::mem::size_of::<f64>())?;
            self.slopes = DMatrix::from_vec(2 * constraints.len(), nv, filled("model", len, 0.0)?);
        } else {
            self.slopes.fill(0.0);
        }
        self.rhs.resize(nv, 0.0);
        self.x.resize(nv, 0.0);
        self.responses.resize_with(6, Vec::new);
        self.momenta.resize_with(6, Vec::new);
        for (responses, momenta) in self.responses.iter_mut().zip(&mut self.momenta) {
            responses.resize(n, Motion::zeros());
            momenta.resize(n, Force::zeros());
        }
        self.forms.resize(nv, Matrix6::zeros());
        self.motions.clear();
        self.motions.resize(constraints.len(), [Motion::zeros(); 3]);
        self.order.clear();
        self.order.extend((0..constraints.len()).filter(|&c| constraints[c].bodies().is_some()));
        let pair = |c: &usize| constraints[*c].bodies().map(|(a, b)| (a, b.map_or(0, |b| b + 1)));
        self.order.sort_unstable_by_key(pair);
        let mut start = 0;
        while start < self.order.len() {
            let end = start + self.order[start..].iter().take_while(|c| pair(c) == pair(&self.order[start])).count();
            let Some((a, b)) = constraints[self.order[start]].bodies() else { unreachable!("ordered constraints are on bodies") };
            let unit = 3 * (end - start) > 6;
            self.basis.clear();
            if unit {
                self.basis.extend((0..6).map(|m| Force::ith(m, 1.0)));
            } else {
                self.basis.extend(self.order[start..end].iter().flat_map(|&c| constraints[c].rows));
            }
            for m in 0..self.basis.len() {
                tree.force.fill(Force::zeros());
                tree.force[a] = self.basis[m];
                if let Some(b) = b {
                    tree.force[b] = -self.basis[m];
                }
                tree.generalized(model, data, &mut self.rhs);
                self.respond(model, data, tree, m);
            }
            self.kinetic_forms(model, data, self.basis.len());
            for (body, sign) in [(Some(a), 2.0), (b, -2.0)] {
                if let Some(body) = body {
                    self.moving_forms(model, data, body, sign);
                }
            }
            for (j, &c) in self.order[start..end].iter().enumerate() {
                for (r, f) in constraints[c].rows.iter().enumerate() {
                    let row = 2 * c + r.min(1);
                    // Its coefficients: the row itself in the unit basis, the basis' (3 j + r)th force otherwise.
                    let relative = |m: usize| b.map_or(self.responses[m][a], |b| self.responses[m][a] - self.responses[m][b]);
                    if unit {
                        for (k, form) in self.forms.iter().enumerate() {
                            self.slopes[(row, k)] += f.dot(&(form * f));
                        }
                        self.motions[c][r] = (0..6).map(|m| relative(m) * f[m]).sum();
                    } else {
                        let m = 3 * j + r;
                        for (k, form) in self.forms.iter().enumerate() {
                            self.slopes[(row, k)] += form[(m, m)];
                        }
                        self.motions[c][r] = relative(m);
                    }
                }
            }
            start = end;
        }
        for (c, constraint) in constraints.iter().enumerate() {
            if let Target::Coordinate(k) = constraint.target {
                // A unit generalized force on its coordinate: the form's one coefficient is the row's.
                self.rhs.fill(0.0);
                self.rhs[k] = 1.0;
                self.respond(model, data, tree, 0);
                self.kinetic_forms(model, data, 1);
                for (j, form) in self.forms.iter().enumerate() {
                    self.slopes[(2 * c, j)] += form[(0, 0)];
                }
            }
        }
        Ok(true)
    }

    /// The response to basis force `m` (its generalized force in `rhs`): the bodies' motions V^m = Φ x^m, which the
    /// solve's forward pass leaves in `tree.motion`, and the subtrees' momenta h^m_i = Σ_{b in i's subtree} I_b V^m_b.
    fn respond(&mut self, model: &Model, data: &Data, tree: &mut Articulated, m: usize) {
        tree.solve(model, data, &self.rhs, &mut self.x);
        self.responses[m].copy_from_slice(&tree.motion);
        for (h, (inertia, v)) in self.momenta[m].iter_mut().zip(data.rigid.iter().zip(&tree.motion)) {
            *h = inertia * v;
        }
        for i in (1..model.nbodies()).rev() {
            let h = self.momenta[m][i];
            self.momenta[m][model.parent(i)] += h;
        }
    }

    /// D_k = −xᵀ (∂M/∂q_k) x = −2 ∂T/∂q_k as forms in the basis: [D_k]_mn = 2 h^m_i · (S_k × V^n_λ(i)) (the module's
    /// formula) for the first `size` responses, overwriting `forms`.
    fn kinetic_forms(&mut self, model: &Model, data: &Data, size: usize) {
        self.forms.iter_mut().for_each(|form| form.fill(0.0));
        for i in 1..model.nbodies() {
            let (k, parent) = (model.idx_v(i), model.parent(i));
            for_each_axis(model, data, i, |c, axis| {
                let form = &mut self.forms[k + c];
                for n in 0..size {
                    let moved = cross_motion(&axis, &self.responses[n][parent]);
                    for m in 0..size {
                        form[(m, n)] += 2.0 * self.momenta[m][i].dot(&moved);
                    }
                }
            });
        }
    }

    /// D_k += `sign` 2 f · ∂V_body/∂q_k as forms, ∂V_body/∂q_k = S_k × (V_body − V_λ) for each coordinate k on `body`'s
    /// path from the root (λ the parent of the coordinate's body, the ground for the free-flyer's rotation):
    /// [D_k]_mn += `sign` β_m · (S_k × (V^n_body − V^n_λ)), β the basis.
    fn moving_forms(&mut self, model: &Model, data: &Data, body: usize, sign: f64) {
        let size = self.basis.len();
        let (forms, basis, responses) = (&mut self.forms, &self.basis, &self.responses);
        let mut add = |k: usize, axis: &Motion, parent: Option<usize>| {
            for n in 0..size {
                let relative = parent.map_or(responses[n][body], |p| responses[n][body] - responses[n][p]);
                let moved = cross_motion(axis, &relative);
                for m in 0..size {
                    forms[k][(m, n)] += sign * basis[m].dot(&moved);
                }
            }
        };
        let mut i = body;
        while i != 0 {
            let (k, parent) = (model.idx_v(i), model.parent(i));
            for_each_axis(model, data, i, |c, axis| add(k + c, &axis, Some(parent)));
            i = parent;
        }
        if model.joint(0).dofs() == Dofs::Free {
            // The rotation's three: the translation moves the frame with the base.
            for c in 3..6 {
                let axis = data.centred_m_i[0].act_motion(&Motion::ith(c, 1.0));
                add(c, &axis, None);
            }
        }
    }
}

/// Calls `f` with each column of body `i`'s joint (not the root's), in the centred frame, and its index in the joint.
#[inline(always)]
fn for_each_axis(model: &Model, data: &Data, i: usize, mut f: impl FnMut(usize, Motion)) {
    match model.joint(i).dofs() {
        Dofs::One(_) => f(0, data.s[i]),
        Dofs::Ball => {
            let subspace = ball_subspace(&data.centred_m_i[i]);
            for c in 0..3 {
                f(c, subspace.column(c).into_owned());
            }
        }
        Dofs::Zero | Dofs::Free => {}
    }
}
