//! The tree-sparse factor M̃ = Lᵀ D L that the articulated-body algorithm leaves behind, and the maps the
//! contact solver works through.
//!
//! `aba_with_armature` eliminates joints from the leaves up (Featherstone, Table 7.1) and keeps, per joint k,
//! U_k = I^A_k S_k and D_k = S_kᵀ U_k + armature_k: with L_ki = D_k⁻¹ U_kᵀ S_i for every ancestor i of k
//! (zero elsewhere: no fill-in), M̃ = Lᵀ D L. A free-flyer base is one 6x6 block, D_0 = I^A_0 = C Cᵀ.
//! The solver works with u = D^½ L v, in which a constraint row J becomes Y = D^-½ L⁻ᵀ Jᵀ, so that
//! J v = Yᵀ u and J M̃⁻¹ Jᵀ = Yᵀ Y. L⁻ᵀ Jᵀ for a force on one body is the ABA backward pass of that force
//! alone: nonzero only on the body's ancestor joints, O(depth) to build, and the Delassus matrix is never
//! formed. Every contact on a body shares its six columns Φ (one per unit spatial force), so the solver
//! keeps Φ per body rather than per contact row. Everything is in the world's axes about the base
//! origin, as `aba` leaves it in `Data`.

use nalgebra::{Cholesky, Matrix6, Vector6};

use crate::model::{Data, Joint, Model};
use crate::spatial::{dot6, Force, Motion};

/// One nonzero row of Φ = D^-½ L⁻ᵀ Jᵀ for a body's six unit spatial forces (its columns): Yᵀ u for any
/// force f on the body is fᵀ (Φᵀ u), and Φᵀ u is the body's spatial velocity.
#[derive(Debug, Clone, Copy)]
pub(super) struct Entry {
    pub index: u32,
    pub value: [f64; 6],
}

pub(super) struct Factor {
    /// D_k^-½ of each one-degree-of-freedom joint's coordinate (indexed by velocity coordinate).
    sqrt_d_inv: Vec<f64>,
    /// The lower-triangular C with D_0 = C Cᵀ for a free-flyer base.
    base: Option<Matrix6<f64>>,
    /// Spatial velocity of each body while mapping to or from u.
    velocity: Vec<Motion>,
}

impl Factor {
    pub(super) fn new(model: &Model) -> Self {
        Factor { sqrt_d_inv: vec![0.0; model.nv()], base: None, velocity: vec![Motion::zeros(); model.nbodies()] }
    }

    /// Reads the factor from `data` after `aba_with_armature`. False if D is not positive definite.
    pub(super) fn update(&mut self, model: &Model, data: &Data) -> bool {
        for i in 1..model.nbodies() {
            if model.joint(i).nv() == 1 {
                self.sqrt_d_inv[model.idx_v(i)] = data.d_inv[i].sqrt();
            }
        }
        self.base = if model.floating_base() { Cholesky::new(data.inertia[0]).map(|c| c.l()) } else { None };
        (!model.floating_base() || self.base.is_some()) && self.sqrt_d_inv.iter().all(|x| x.is_finite())
    }

    /// u = D^½ L v: (L v)_k = v_k + D_k⁻¹ U_kᵀ V_λ(k), with V_λ the velocity of joint k's parent body.
    pub(super) fn u_from_velocity(&mut self, model: &Model, data: &Data, v: &[f64], u: &mut [f64]) {
        for i in 0..model.nbodies() {
            let k = model.idx_v(i);
            self.velocity[i] = match model.joint(i) {
                Joint::FreeFlyer => {
                    let world = data.o_m_i[0].act_motion(&Motion::from_column_slice(&v[k..k + 6]));
                    let c = self.base.as_ref().expect("floating base factor");
                    u[k..k + 6].copy_from_slice((c.transpose() * world).as_slice());
                    world
                }
                Joint::Fixed => self.velocity[model.parent(i)],
                Joint::Revolute(_) | Joint::Prismatic(_) => {
                    let parent = self.velocity[model.parent(i)];
                    let lv = v[k] + data.d_inv[i] * dot6(&data.u[i], parent.as_slice());
                    u[k] = lv / self.sqrt_d_inv[k];
                    parent + data.s[i] * v[k]
                }
            };
        }
    }

    /// v = L⁻¹ D^-½ u, root to leaves (the ABA forward pass).
    pub(super) fn velocity_from_u(&mut self, model: &Model, data: &Data, u: &[f64], v: &mut [f64]) {
        for i in 0..model.nbodies() {
            let k = model.idx_v(i);
            self.velocity[i] = match model.joint(i) {
                Joint::FreeFlyer => {
                    let c = self.base.as_ref().expect("floating base factor");
                    let world = c.transpose().solve_upper_triangular(&Vector6::from_column_slice(&u[k..k + 6])).expect("positive diagonal");
                    v[k..k + 6].copy_from_slice(data.o_m_i[0].inv_act_motion(&world).as_slice());
                    world
                }
                Joint::Fixed => self.velocity[model.parent(i)],
                Joint::Revolute(_) | Joint::Prismatic(_) => {
                    let parent = self.velocity[model.parent(i)];
                    v[k] = u[k] * self.sqrt_d_inv[k] - data.d_inv[i] * dot6(&data.u[i], parent.as_slice());
                    parent + data.s[i] * v[k]
                }
            };
        }
    }

    /// Appends Φ for the six unit spatial forces (world axes about the base origin) acting on body `a`
    /// and, opposite, on body `b`: the backward pass of each force up both chains, merged where they meet.
    pub(super) fn push_chain(&self, model: &Model, data: &Data, a: usize, b: Option<usize>, out: &mut Vec<Entry>) {
        let mut pa: [Force; 6] = std::array::from_fn(|j| Force::from_fn(|r, _| if r == j { 1.0 } else { 0.0 }));
        let mut pb = pa.map(|f| -f);
        let (mut a, mut b) = (a, b);
        // Walk the deeper chain up until the two meet (parents have lower indices), then carry their sum.
        loop {
            match b {
                Some(bb) if bb > a => {
                    self.eliminate(model, data, bb, &mut pb, out);
                    b = Some(model.parent(bb));
                    continue;
                }
                Some(bb) if bb == a => {
                    for (x, y) in pa.iter_mut().zip(&pb) {
                        *x += y;
                    }
                    b = None;
                }
                _ => {}
            }
            self.eliminate(model, data, a, &mut pa, out);
            if a == 0 {
                return;
            }
            a = model.parent(a);
        }
    }

    /// Appends the one column of Φ for a unit generalized force on the coordinate of body `i`'s joint (a
    /// joint-limit row), in the entries' first slot.
    pub(super) fn push_coordinate(&self, model: &Model, data: &Data, i: usize, out: &mut Vec<Entry>) {
        let k = model.idx_v(i);
        out.push(Entry { index: k as u32, value: [self.sqrt_d_inv[k], 0.0, 0.0, 0.0, 0.0, 0.0] });
        let mut forces = [Force::zeros(); 6];
        forces[0] = -data.u[i] * data.d_inv[i];
        let mut j = model.parent(i);
        loop {
            self.eliminate(model, data, j, &mut forces, out);
            if j == 0 {
                return;
            }
            j = model.parent(j);
        }
    }

    /// One joint of the backward pass: y_k = S_kᵀ P (the rows' entries, scaled by D^-½), then the parent
    /// receives P − U_k D_k⁻¹ y_k (eq. 7.42 with only external forces).
    #[inline(always)]
    fn eliminate(&self, model: &Model, data: &Data, i: usize, forces: &mut [Force; 6], out: &mut Vec<Entry>) {
        let k = model.idx_v(i);
        match model.joint(i) {
            Joint::Revolute(_) | Joint::Prismatic(_) => {
                let mut value = [0.0; 6];
                for (r, f) in forces.iter_mut().enumerate() {
                    let y = dot6(&data.s[i], f.as_slice());
                    value[r] = y * self.sqrt_d_inv[k];
                    *f -= data.u[i] * (y * data.d_inv[i]);
                }
                out.push(Entry { index: k as u32, value });
            }
            Joint::FreeFlyer => {
                // The base's six coordinates in world axes: y_0 = P, Y_0 = C⁻¹ P.
                let c = self.base.as_ref().expect("floating base factor");
                let columns: [Vector6<f64>; 6] = forces.map(|f| c.solve_lower_triangular(&f).expect("positive diagonal"));
                for j in 0..6 {
                    out.push(Entry { index: (k + j) as u32, value: std::array::from_fn(|r| columns[r][j]) });
                }
            }
            Joint::Fixed => {}
        }
    }
}
