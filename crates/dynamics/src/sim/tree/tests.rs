//! The Newton solver's passes over the tree against dense linear algebra: M̃ x, M̃⁻¹ r and H⁻¹ r (`articulated`)
//! against the CRBA mass matrix, and the Delassus diagonals (`delassus`) against J M̃⁻¹ Jᵀ formed densely,
//! on a fixed-base branching tree (revolute and prismatic joints), on a floating one, and on trees with ball joints.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Rotation3, UnitQuaternion, Vector3, Vector6};

use super::articulated::Articulated;
use super::constraint::{Constraint, Kind, Target};
use super::delassus::Delassus;
use super::delassus_derivatives::DiagonalSlopes;
use crate::algorithms::{
    aba_with_armature_unchecked as aba_with_armature, crba_unchecked as crba, integrate_unchecked as integrate,
    placement_update_unchecked as placement_update,
};
use crate::model::{Data, JointLimits, Model};
use crate::sim::tests::ten_link_tree;
use crate::spatial::spatial;
use crate::Joint;
use crate::{MassProperties, Transform};

/// A box base on a free-flyer with a chain of three and a side branch.
fn floating_tree() -> Model {
    let part = |m: f64| MassProperties::solid_box(m, Vector3::new(0.2, 0.05, 0.04), Vector3::new(0.1, 0.0, 0.0), &Matrix3::identity()).unwrap();
    let mut model =
        Model::new(true, MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap(), "base");
    let along = |r: Matrix3<f64>| Transform::new(r, Vector3::new(0.2, 0.0, 0.0));
    let a = model
        .add_body(
            0,
            Joint::Revolute(Vector3::y()),
            along(Rotation3::from_euler_angles(0.0, 0.3, 0.0).into_inner()),
            part(0.5),
            "a",
            JointLimits::NONE,
        )
        .unwrap();
    let b = model.add_body(a, Joint::Revolute(Vector3::new(0.3, 1.0, 0.0)), along(Matrix3::identity()), part(0.4), "b", JointLimits::NONE).unwrap();
    model.add_body(b, Joint::Prismatic(Vector3::x()), along(Matrix3::identity()), part(0.3), "c", JointLimits::NONE).unwrap();
    model
        .add_body(
            0,
            Joint::Revolute(Vector3::z()),
            along(Rotation3::from_euler_angles(0.0, 0.0, 2.0).into_inner()),
            part(0.6),
            "d",
            JointLimits::NONE,
        )
        .unwrap();
    model
}

/// Ball joints on a floating base (one between two revolutes, one on a leaf) or on a fixed one.
fn ball_tree(floating: bool) -> Model {
    let part = |m: f64| MassProperties::solid_box(m, Vector3::new(0.2, 0.05, 0.04), Vector3::new(0.1, 0.0, 0.0), &Matrix3::identity()).unwrap();
    let mut model =
        Model::new(floating, MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap(), "base");
    let along = |r: Matrix3<f64>| Transform::new(r, Vector3::new(0.2, 0.0, 0.0));
    let tilted = along(Rotation3::from_euler_angles(0.4, 0.3, -0.2).into_inner());
    let a = model.add_body(0, Joint::Revolute(Vector3::y()), tilted, part(0.5), "a", JointLimits::NONE).unwrap();
    let b = model.add_body(a, Joint::Spherical, tilted, part(0.4), "b", JointLimits::NONE).unwrap();
    model.add_body(b, Joint::Revolute(Vector3::new(0.3, 1.0, 0.0)), along(Matrix3::identity()), part(0.3), "c", JointLimits::NONE).unwrap();
    model.add_body(0, Joint::Spherical, along(Rotation3::from_euler_angles(0.0, 0.0, 2.0).into_inner()), part(0.6), "d", JointLimits::NONE).unwrap();
    model
}

/// A configuration away from the neutral one (unit quaternions for a free-flyer and ball joints).
fn configuration(model: &Model) -> Vec<f64> {
    let mut q: Vec<f64> = (0..model.nq()).map(|k| 0.4 * ((k as f64) * 1.3 + 0.2).sin()).collect();
    for i in 0..model.nbodies() {
        let at = match model.joint(i) {
            Joint::FreeFlyer => 3,
            Joint::Spherical => 0,
            _ => continue,
        } + model.idx_q(i);
        let r = UnitQuaternion::from_euler_angles(0.3, -0.2 + 0.1 * i as f64, 0.7);
        q[at..at + 4].copy_from_slice(&[r.i, r.j, r.k, r.w]);
    }
    q
}

fn models() -> [Model; 4] {
    [ten_link_tree(), floating_tree(), ball_tree(true), ball_tree(false)]
}

/// A deterministic symmetric positive semi-definite 6x6 (A Aᵀ of a pseudo-random A).
fn stiffness(seed: usize) -> Matrix6<f64> {
    let a = Matrix6::from_fn(|r, c| ((seed * 36 + r * 6 + c) as f64 * 0.618).sin());
    a * a.transpose()
}

/// Dense M̃ = M + diag(armature), and Φ_b (6 x nv) of every body from `motions` of the unit vectors.
fn dense(model: &Model, q: &[f64], armature: &[f64], tree: &mut Articulated, data: &Data) -> (DMatrix<f64>, Vec<DMatrix<f64>>) {
    let nv = model.nv();
    let mut mass = crba(model, &mut Data::new(model), q).clone();
    for k in 0..nv {
        mass[(k, k)] += armature[k];
    }
    let mut phi = vec![DMatrix::zeros(6, nv); model.nbodies()];
    for k in 0..nv {
        let unit: Vec<f64> = (0..nv).map(|j| if j == k { 1.0 } else { 0.0 }).collect();
        tree.motions(model, data, &unit);
        for (b, phi) in phi.iter_mut().enumerate() {
            phi.set_column(k, &tree.motion[b]);
        }
    }
    (mass, phi)
}

fn prepared(model: &Model) -> (Vec<f64>, Vec<f64>, Data, Articulated) {
    let q = configuration(model);
    // Armature is a joint's: a free-flyer's six coordinates have none (as in the simulation).
    let armature: Vec<f64> = (0..model.nv()).map(|k| if k < base_coordinates(model) { 0.0 } else { 0.01 + 0.002 * k as f64 }).collect();
    let mut data = Data::new(model);
    let zeros = vec![0.0; model.nv()];
    aba_with_armature(model, &mut data, &q, &zeros, &zeros, None, &armature);
    (q, armature, data, Articulated::new(model))
}

fn base_coordinates(model: &Model) -> usize {
    if model.floating_base() {
        6
    } else {
        0
    }
}

fn relative_error(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    (a - b).amax() / b.amax().max(1e-300)
}

#[test]
fn newton_matrix_products_and_solves_match_dense_algebra() {
    for model in models() {
        let nv = model.nv();
        let (q, armature, data, mut tree) = prepared(&model);
        let (mass, phi) = dense(&model, &q, &armature, &mut tree, &data);
        // M̃ x against CRBA: this also checks the Φ_b the rest of the test builds on.
        let x = DVector::from_fn(nv, |k, _| (k as f64 * 0.7).cos());
        let mut product = vec![0.0; nv];
        tree.mass_times(&model, &data, &armature, x.as_slice(), &mut product);
        assert!(relative_error(&DVector::from_vec(product), &(&mass * &x)) < 1e-12);
        let rhs = DVector::from_fn(nv, |k, _| (k as f64 * 1.9 + 0.3).sin());
        let mut solution = vec![0.0; nv];
        // M̃⁻¹ r through the factor ABA left.
        assert!(tree.factor_of_aba(&model, &data, &armature, data.inertia[0].cholesky().as_ref()));
        tree.solve(&model, &data, rhs.as_slice(), &mut solution);
        assert!(relative_error(&(&mass * DVector::from_vec(solution.clone())), &rhs) < 1e-10, "floating base: {}", model.floating_base());
        // H = M̃ + Σ Φ_bᵀ K_b Φ_b + diag(c): H⁻¹ r solves H x = r, for symmetric K_b and for K_b with an
        // unsymmetric rank-one part (a sliding contact's friction following its normal impulse, `solver`).
        for skew in [0.0, 0.3] {
            let mut h = mass.clone();
            tree.clear_stiffness();
            for (b, phi) in phi.iter().enumerate() {
                let a = Vector6::from_fn(|r, _| ((b * 6 + r) as f64 * 1.3).cos());
                let n = Vector6::from_fn(|r, _| ((b * 6 + r) as f64 * 0.4).sin());
                let k = stiffness(b) + skew * a * n.transpose();
                tree.stiffness[b] += k;
                h += phi.transpose() * DMatrix::from_column_slice(6, 6, k.as_slice()) * phi;
            }
            for k in base_coordinates(&model)..nv {
                tree.coordinate_stiffness[k] = 0.5 * k as f64;
                h[(k, k)] += 0.5 * k as f64;
            }
            assert!(tree.factor(&model, &data, &armature, skew == 0.0));
            assert!(tree.stiffness.iter().all(|k| *k == Matrix6::zeros()), "the factor leaves no stiffness behind");
            tree.solve(&model, &data, rhs.as_slice(), &mut solution);
            let error = relative_error(&(&h * DVector::from_vec(solution.clone())), &rhs);
            assert!(error < 1e-10, "floating base: {}, skew {skew}: {error}", model.floating_base());
        }
    }
}

#[test]
fn delassus_diagonals_match_dense_inverse_mass_matrix() {
    for model in models() {
        let (q, armature, data, mut tree) = prepared(&model);
        let (mass, phi) = dense(&model, &q, &armature, &mut tree, &data);
        let inverse = mass.clone().try_inverse().expect("positive definite");
        let mut delassus = Delassus::new(&model);
        assert!(delassus.update(&model, &data, &armature));
        // A contact frame: an orthonormal (n, t1, t2) at an arm r, rows [d; r × d].
        let normal = Vector3::new(0.3, -0.5, 0.8).normalize();
        let t1 = normal.cross(&Vector3::new(1.0, 0.2, -0.1)).normalize();
        let arm = Vector3::new(0.7, -0.4, 0.25);
        let rows = [normal, t1, normal.cross(&t1)].map(|d| spatial(d, arm.cross(&d)));
        let n = model.nbodies();
        for a in 1..n {
            for b in [None, Some(0), Some(1), Some(n - 1), Some(a / 2)] {
                if b == Some(a) {
                    continue;
                }
                let jacobian = b.map_or(phi[a].clone(), |b| &phi[a] - &phi[b]);
                let (diagonal, _) = delassus.contact(&model, &data, a, b, &rows, &arm);
                let expected: [f64; 3] = std::array::from_fn(|r| {
                    let row = jacobian.transpose() * DVector::from_column_slice(rows[r].as_slice());
                    (row.transpose() * &inverse * &row)[(0, 0)]
                });
                for (got, want) in diagonal.into_iter().zip([expected[0], expected[1] + expected[2]]) {
                    assert!(
                        (got - want).abs() < 1e-10 * want.abs().max(1e-12),
                        "floating base {}: body {a} other {b:?}: {got} vs {want}",
                        model.floating_base(),
                    );
                }
            }
            if model.joint(a).nv() == 1 {
                let k = model.idx_v(a);
                assert!((delassus.coordinate(&model, &data, a) - inverse[(k, k)]).abs() < 1e-10 * inverse[(k, k)]);
            }
        }
    }
}

/// The body whose joint coordinate `k` is.
fn body_of(model: &Model, k: usize) -> usize {
    (0..model.nbodies()).find(|&i| (model.idx_v(i)..model.idx_v(i) + model.joint(i).nv()).contains(&k)).unwrap()
}

/// The poses and subspaces updated over a displaced joint's subtree (`placement_update`, what the transition
/// Jacobians' differences use) against the full ABA at each displaced configuration, coordinate after coordinate (each
/// update putting back the last one's bodies). A free-flyer's position moves none of them.
#[test]
fn the_poses_updated_over_a_subtree_are_the_full_placement() {
    for model in models() {
        let (q, _, reference, _) = prepared(&model);
        let (nv, zeros) = (model.nv(), vec![0.0; model.nv()]);
        let mut data = Data::new(&model);
        let mut written: Vec<usize> = (0..model.nbodies()).collect();
        let (mut displaced, mut direction) = (vec![0.0; model.nq()], vec![0.0; nv]);
        for k in 0..nv {
            direction[k] = 1.0;
            // Large enough that an update missing a body would show.
            integrate(&model, &q, &direction, 0.3, &mut displaced);
            direction[k] = 0.0;
            let moved = if model.floating_base() && k < 3 { None } else { Some(body_of(&model, k)) };
            placement_update(&model, &mut data, &reference, &displaced, moved, &mut written);
            let mut expected = Data::new(&model);
            aba_with_armature(&model, &mut expected, &displaced, &zeros, &zeros, None, &zeros);
            let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-12 * (1.0 + y.abs()));
            for i in 0..model.nbodies() {
                let label = format!("floating base {}, coordinate {k}, body {i}", model.floating_base());
                let (pose, want) = (&data.centred_m_i[i], &expected.centred_m_i[i]);
                assert!(
                    close(pose.rotation.as_slice(), want.rotation.as_slice()) && close(pose.translation.as_slice(), want.translation.as_slice()),
                    "{label}: pose"
                );
                assert!(close(data.s[i].as_slice(), expected.s[i].as_slice()), "{label}: S");
            }
        }
    }
}

/// The analytic slopes of the Delassus diagonals by the configuration at fixed rows (`DiagonalSlopes`) against central
/// differences of `Delassus::contact` and `Delassus::coordinate` on the full factor at displaced configurations: contacts
/// with the ground (three on each body, more rows than a pair's basis of six forces) and between bodies, and every
/// one-degree-of-freedom joint's limit row; and each contact row's motions V_a − V_b against a solve of its own. A
/// free-flyer's position moves none of them.
#[test]
fn delassus_diagonal_slopes_match_differences_of_the_diagonals() {
    const STEP: f64 = 1e-5;
    for model in models() {
        let (q, armature, data, mut tree) = prepared(&model);
        let (n, nv, zeros) = (model.nbodies(), model.nv(), vec![0.0; model.nv()]);
        let normal = Vector3::new(0.3, -0.5, 0.8).normalize();
        let t1 = normal.cross(&Vector3::new(1.0, 0.2, -0.1)).normalize();
        let contact = |arm: Vector3<f64>, target| {
            let rows = [normal, t1, normal.cross(&t1)].map(|d| spatial(d, arm.cross(&d)));
            Constraint::new(Kind::Contact { mu: 0.5, arm, coulomb: false }, target, rows, 0.0, [0.0; 3], [1.0; 2], 1.0)
        };
        let arms = [Vector3::new(0.7, -0.4, 0.25), Vector3::new(-0.2, 0.5, -0.3), Vector3::new(0.1, 0.1, 0.9)];
        let mut constraints = Vec::new();
        for a in 1..n {
            for b in [None, Some(a / 2), Some(n - 1)] {
                if b != Some(a) {
                    constraints.push(contact(arms[0], Target::Bodies(a, b)));
                }
            }
            constraints.extend(arms[1..].iter().map(|&arm| contact(arm, Target::Bodies(a, None))));
            if model.joint(a).nv() == 1 {
                let unit = Vector6::new(-1.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                let target = Target::Coordinate(model.idx_v(a));
                constraints.push(Constraint::new(Kind::Limit, target, [unit, Vector6::zeros(), Vector6::zeros()], 0.0, [0.0; 3], [1.0, 0.0], 1.0));
            }
        }
        let diagonals = |q: &[f64]| -> Vec<[f64; 2]> {
            let mut data = Data::new(&model);
            aba_with_armature(&model, &mut data, q, &zeros, &zeros, None, &armature);
            let mut delassus = Delassus::new(&model);
            assert!(delassus.update(&model, &data, &armature));
            constraints
                .iter()
                .map(|c| match c.target {
                    Target::Bodies(a, b) => {
                        let Kind::Contact { arm, .. } = c.kind else { unreachable!("contacts are on bodies") };
                        delassus.contact(&model, &data, a, b, &c.rows, &arm).0
                    }
                    Target::Coordinate(k) => [delassus.coordinate(&model, &data, body_of(&model, k)), 0.0],
                })
                .collect()
        };
        let mut delassus = Delassus::new(&model);
        assert!(delassus.update(&model, &data, &armature));
        let mut slopes = DiagonalSlopes::default();
        assert!(slopes.compute(&model, &data, &armature, delassus.base(), &mut tree, &constraints).unwrap());
        let (mut rhs, mut x) = (vec![0.0; nv], vec![0.0; nv]);
        for (c, constraint) in constraints.iter().enumerate() {
            let Some((a, b)) = constraint.bodies() else { continue };
            for (r, f) in constraint.rows.iter().enumerate() {
                tree.force.fill(Vector6::zeros());
                tree.force[a] = *f;
                if let Some(b) = b {
                    tree.force[b] = -f;
                }
                tree.generalized(&model, &data, &mut rhs);
                tree.solve(&model, &data, &rhs, &mut x);
                let want = b.map_or(tree.motion[a], |b| tree.motion[a] - tree.motion[b]);
                let got = slopes.motions[c][r];
                assert!((got - want).norm() <= 1e-12 * want.norm().max(1.0), "constraint {c} row {r}: {got} vs {want}");
            }
        }
        let (mut displaced, mut direction) = (vec![0.0; model.nq()], vec![0.0; nv]);
        for k in 0..nv {
            let mut side = |sign: f64| {
                direction[k] = 1.0;
                integrate(&model, &q, &direction, sign * STEP, &mut displaced);
                direction[k] = 0.0;
                diagonals(&displaced)
            };
            let (plus, minus) = (side(1.0), side(-1.0));
            for (c, (plus, minus)) in plus.iter().zip(&minus).enumerate() {
                for r in 0..2 {
                    let (got, want) = (slopes.slopes[(2 * c + r, k)], (plus[r] - minus[r]) / (2.0 * STEP));
                    let label =
                        format!("floating base {}, constraint {c} ({:?}) row {r}, coordinate {k}", model.floating_base(), constraints[c].target);
                    assert!((got - want).abs() <= 1e-6 * plus[r].abs().max(1e-12), "{label}: {got} vs {want}");
                    if model.floating_base() && k < 3 {
                        assert_eq!(got, 0.0, "{label}: the base's position");
                    }
                }
            }
        }
    }
}
