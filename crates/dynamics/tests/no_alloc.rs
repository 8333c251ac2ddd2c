//! The algorithms allocate nothing once `Data` exists: a counting global allocator watches every call.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use legkit_dynamics::algorithms::{
    aba, aba_derivatives, aba_derivatives_into, center_of_mass, center_of_mass_jacobian, centroidal_derivatives, centroidal_map, centroidal_momentum,
    centroidal_momentum_rate, crba, difference, difference_jacobians, forward_kinematics, frame_acceleration, frame_acceleration_derivatives,
    frame_velocity, frame_velocity_derivatives, integrate, integrate_jacobians, jacobian, jacobian_time_variation, kinetic_energy, minv,
    potential_energy, rnea, rnea_derivatives, rnea_derivatives_into, rnea_second_order_derivatives, subtree_mass_properties, Frame,
};
use legkit_dynamics::algorithms::{contact_dynamics_derivatives_into, impact_derivatives_into, ContactDim, ContactPoint};
use legkit_dynamics::geometry::{Shape, ShapeKind};
use legkit_dynamics::model::Dense;
use legkit_dynamics::{Data, Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{DMatrix, Matrix3, Vector3};

#[path = "fixtures/quadruped.rs"]
mod fixture;

struct Counting;

thread_local! {
    /// Allocations made by this thread: the test harness's own threads allocate while tests run.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // try_with: a thread being torn down has no counter left to bump.
        let _ = ALLOCATIONS.try_with(|count| count.set(count.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations on this thread while `f` runs (the algorithms are single-threaded).
fn allocations_during(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.with(Cell::get);
    f();
    ALLOCATIONS.with(Cell::get) - before
}

/// A floating binary tree of 30 boxes on revolute and prismatic joints.
fn tree() -> Model {
    let body = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.0, 0.0, 0.1), &Matrix3::identity()).unwrap();
    let mut model = Model::new(true, body, "base");
    for i in 1..30 {
        let joint = if i % 4 == 0 { Joint::Prismatic(Vector3::z()) } else { Joint::Revolute(Vector3::new(1.0, 2.0, 0.5)) };
        let placement = Transform::from_translation(Vector3::new(0.1, 0.0, 0.05));
        model.add_body((i - 1) / 2, joint, placement, body, &format!("b{i}"), JointLimits::NONE).unwrap();
    }
    model
}

#[test]
fn algorithms_do_not_allocate() {
    let model = tree();
    let mut data = Data::new(&model);
    let mut q = vec![0.1; model.nq()];
    q[3..7].copy_from_slice(&[0.0, 0.0, 0.0, 1.0]);
    let v = vec![0.2; model.nv()];
    let tau = vec![0.3; model.nv()];
    // The first calls size M, M⁻¹ and minv's force sets, and the derivatives' workspace, outputs and tensors (the ABA
    // derivatives form ∂τ in their own outputs, so the RNEA derivatives' are sized by their own first call).
    crba(&model, &mut data, &q).unwrap();
    minv(&model, &mut data, &q).unwrap();
    aba_derivatives(&model, &mut data, &q, &v, &tau, None).unwrap();
    rnea_derivatives(&model, &mut data, &q, &v, &tau, None).unwrap();
    rnea_second_order_derivatives(&model, &mut data, &q, &v, &tau).unwrap();
    let (mut q1, mut dv) = (vec![0.0; model.nq()], vec![0.0; model.nv()]);
    let (mut jacobian_a, mut jacobian_b) = (DMatrix::zeros(model.nv(), model.nv()), DMatrix::zeros(model.nv(), model.nv()));
    let count = allocations_during(|| {
        forward_kinematics(&model, &mut data, &q).unwrap();
        rnea(&model, &mut data, &q, &v, &tau, None).unwrap();
        aba(&model, &mut data, &q, &v, &tau, None).unwrap();
        crba(&model, &mut data, &q).unwrap();
        minv(&model, &mut data, &q).unwrap();
        jacobian(&model, &mut data, &q, 17, &Vector3::new(0.1, 0.0, 0.0), Frame::LocalWorldAligned).unwrap();
        center_of_mass(&model, &mut data, &q).unwrap();
        center_of_mass_jacobian(&model, &mut data, &q).unwrap();
        subtree_mass_properties(&model, &mut data, &q).unwrap();
        centroidal_momentum(&model, &mut data, &q, &v).unwrap();
        centroidal_map(&model, &mut data, &q).unwrap();
        centroidal_momentum_rate(&model, &mut data, &q, &v, &tau).unwrap();
        kinetic_energy(&model, &mut data, &q, &v).unwrap();
        potential_energy(&model, &mut data, &q).unwrap();
        rnea_derivatives(&model, &mut data, &q, &v, &tau, None).unwrap();
        rnea_second_order_derivatives(&model, &mut data, &q, &v, &tau).unwrap();
        aba_derivatives(&model, &mut data, &q, &v, &tau, None).unwrap();
        let point = Vector3::new(0.1, 0.0, 0.0);
        frame_velocity(&model, &mut data, &q, &v, 17, &point, Frame::World).unwrap();
        frame_acceleration(&model, &mut data, &q, &v, &tau, 17, &point, Frame::Local).unwrap();
        frame_velocity_derivatives(&model, &mut data, &q, &v, 17, &point, Frame::LocalWorldAligned).unwrap();
        frame_acceleration_derivatives(&model, &mut data, &q, &v, &tau, 17, &point, Frame::World).unwrap();
        jacobian_time_variation(&model, &mut data, &q, &v, 17, &point, Frame::Local).unwrap();
        centroidal_derivatives(&model, &mut data, &q, &v, &tau).unwrap();
        integrate(&model, &q, &v, 0.1, &mut q1).unwrap();
        difference(&model, &q, &q1, &mut dv).unwrap();
        integrate_jacobians(&model, &v, 0.1, &mut jacobian_a, &mut jacobian_b).unwrap();
        difference_jacobians(&model, &q, &q1, &mut jacobian_a, &mut jacobian_b).unwrap();
    });
    assert_eq!(count, 0, "the algorithms allocated {count} times");
}

#[test]
fn tree_engine_steps_do_not_allocate_once_warm() {
    // A floating box on four legs with ball feet, on servos, standing on the plane: after the buffers have
    // grown to the contact set, steps allocate nothing.
    use legkit_dynamics::sim::{Ground, Options, Servo, Simulation};
    let (model, shapes) = fixture::quadruped(0.3, JointLimits::position(-2.0, 2.0).unwrap());
    let mut options = Options::new(1e-3);
    options.ground = Some(Ground::plane(0.8).unwrap());
    options.shapes = shapes;
    let nv = model.nv();
    let mut sim = Simulation::new(&model, options).unwrap();
    let mut q = model.neutral().as_slice().to_vec();
    q[2] = 0.03 + 0.3 + 0.02;
    sim.set_state(Some(&q), None).unwrap();
    let (mut kp, mut kd) = (vec![40.0; nv], vec![1.0; nv]);
    kp[..6].fill(0.0);
    kd[..6].fill(0.0);
    sim.set_servo(Servo::new(&model, kp, kd, vec![20.0; nv], vec![0.0; nv], vec![0.0; nv]).unwrap()).unwrap();
    let tau = vec![0.0; nv];
    sim.step(Some(&tau), 1000).unwrap();
    assert_eq!(sim.contacts().len(), 4);
    assert_eq!(allocations_during(|| sim.step(Some(&tau), 200).unwrap()), 0);
}

#[test]
fn derivative_kernels_allocate_nothing_once_reserved() {
    // What the bindings do: `reserve_dense` sizes every part fallibly, then each kernel, first call or second,
    // allocates nothing (the contact kernels size their r-dependent workspace fallibly on their first call).
    let model = tree();
    // The model's own cache (its subtree columns, computed once per model), not a kernel's temporary.
    model.subtree_columns(0);
    let (nq, nv) = (model.nq(), model.nv());
    let mut q: Vec<f64> = (0..nq).map(|i| 0.1 + 0.03 * i as f64).collect();
    q[3..7].copy_from_slice(&[0.1, -0.2, 0.3, 0.9]);
    let norm = q[3..7].iter().map(|x| x * x).sum::<f64>().sqrt();
    q[3..7].iter_mut().for_each(|x| *x /= norm);
    let v: Vec<f64> = (0..nv).map(|i| 0.2 - 0.01 * i as f64).collect();
    let tau: Vec<f64> = (0..nv).map(|i| 0.3 * (i as f64).sin()).collect();
    let contacts: Vec<ContactPoint> = [17, 20, 25, 29].iter().map(|&body| ContactPoint { body, point: Vector3::new(0.05, 0.0, 0.1) }).collect();
    let r = 3 * contacts.len();
    let point = Vector3::new(0.1, 0.0, 0.0);
    let (model, q, v, tau, point) = (&model, &q[..], &v[..], &tau[..], &point);
    let square = || vec![0.0; nv * nv];
    let (mut a, mut b) = (square(), square());
    let (mut c, mut d, mut e) = (square(), square(), square());
    type Kernel<'a> = Box<dyn FnMut(&mut Data) + 'a>;
    let mut kernels: Vec<(&str, Kernel)> = vec![
        ("rnea_derivatives_into", Box::new(move |data| rnea_derivatives_into(model, data, q, v, tau, None, &mut a, &mut b).unwrap())),
        ("aba_derivatives_into", Box::new(move |data| aba_derivatives_into(model, data, q, v, tau, None, &mut c, &mut d, &mut e).unwrap())),
        (
            "rnea_derivatives",
            Box::new(|data| {
                rnea_derivatives(model, data, q, v, tau, None).unwrap();
            }),
        ),
        (
            "aba_derivatives",
            Box::new(|data| {
                aba_derivatives(model, data, q, v, tau, None).unwrap();
            }),
        ),
        (
            "rnea_second_order_derivatives",
            Box::new(|data| {
                rnea_second_order_derivatives(model, data, q, v, tau).unwrap();
            }),
        ),
        (
            "frame_velocity_derivatives",
            Box::new(|data| {
                frame_velocity_derivatives(model, data, q, v, 17, point, Frame::Local).unwrap();
            }),
        ),
        (
            "frame_acceleration_derivatives",
            Box::new(|data| {
                frame_acceleration_derivatives(model, data, q, v, tau, 17, point, Frame::World).unwrap();
            }),
        ),
        (
            "jacobian_time_variation",
            Box::new(|data| {
                jacobian_time_variation(model, data, q, v, 17, point, Frame::LocalWorldAligned).unwrap();
            }),
        ),
        (
            "centroidal_derivatives",
            Box::new(|data| {
                centroidal_derivatives(model, data, q, v, tau).unwrap();
            }),
        ),
    ];
    let dense = [Dense::Workspace, Dense::MassMatrix, Dense::Inverse, Dense::RneaDerivatives, Dense::AbaDerivatives, Dense::SecondOrder];
    for (name, kernel) in &mut kernels {
        let mut data = Data::new(model);
        data.reserve_dense(model, &dense).unwrap();
        assert_eq!(allocations_during(|| kernel(&mut data)), 0, "{name}'s first call allocated");
        assert_eq!(allocations_during(|| kernel(&mut data)), 0, "{name}'s second call allocated");
    }
    drop(kernels);
    let mut data = Data::new(model);
    data.reserve_dense(model, &[Dense::Workspace, Dense::Inverse]).unwrap();
    let (mut generalized, mut rows) = (vec![0.0; 3 * nv * nv], vec![0.0; 3 * r * nv]);
    let (ddq_d, forces_d) = (&mut generalized[..], &mut rows[..]);
    let mut contact =
        |data: &mut Data| contact_dynamics_derivatives_into(model, data, q, v, tau, &contacts, ContactDim::Point, ddq_d, forces_d).unwrap();
    contact(&mut data);
    assert_eq!(allocations_during(|| contact(&mut data)), 0, "contact_dynamics_derivatives_into's second call allocated");
    let (velocity_d, impulses_d) = (&mut generalized[..2 * nv * nv], &mut rows[..2 * r * nv]);
    let mut impact = |data: &mut Data| impact_derivatives_into(model, data, q, v, &contacts, ContactDim::Point, velocity_d, impulses_d).unwrap();
    impact(&mut data);
    assert_eq!(allocations_during(|| impact(&mut data)), 0, "impact_derivatives_into's second call allocated");
}
