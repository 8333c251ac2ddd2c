//! The algorithms allocate nothing once `Data` exists: a counting global allocator watches every call.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use legkit_dynamics::algorithms::{
    aba, aba_derivatives, center_of_mass, center_of_mass_jacobian, centroidal_derivatives, centroidal_map, centroidal_momentum,
    centroidal_momentum_rate, crba, difference, difference_jacobians, forward_kinematics, frame_acceleration, frame_acceleration_derivatives,
    frame_velocity, frame_velocity_derivatives, integrate, integrate_jacobians, jacobian, jacobian_time_variation, kinetic_energy, minv,
    potential_energy, rnea, rnea_derivatives, rnea_second_order_derivatives, subtree_mass_properties, Frame,
};
use legkit_dynamics::geometry::{Shape, ShapeKind};
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

#[test]
fn algorithms_do_not_allocate() {
    let body = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.0, 0.0, 0.1), &Matrix3::identity()).unwrap();
    let mut model = Model::new(true, body, "base");
    for i in 1..30 {
        let joint = if i % 4 == 0 { Joint::Prismatic(Vector3::z()) } else { Joint::Revolute(Vector3::new(1.0, 2.0, 0.5)) };
        let placement = Transform::from_translation(Vector3::new(0.1, 0.0, 0.05));
        model.add_body((i - 1) / 2, joint, placement, body, &format!("b{i}"), JointLimits::NONE).unwrap();
    }
    let mut data = Data::new(&model);
    let mut q = vec![0.1; model.nq()];
    q[3..7].copy_from_slice(&[0.0, 0.0, 0.0, 1.0]);
    let v = vec![0.2; model.nv()];
    let tau = vec![0.3; model.nv()];
    // The first calls size M, M⁻¹ and minv's force sets, and the derivatives' workspace, outputs and tensors (the ABA
    // derivatives form ∂τ in their own outputs, so the RNEA derivatives' are sized by their own first call).
    crba(&model, &mut data, &q);
    minv(&model, &mut data, &q);
    aba_derivatives(&model, &mut data, &q, &v, &tau, None);
    rnea_derivatives(&model, &mut data, &q, &v, &tau, None);
    rnea_second_order_derivatives(&model, &mut data, &q, &v, &tau);
    let (mut q1, mut dv) = (vec![0.0; model.nq()], vec![0.0; model.nv()]);
    let (mut jacobian_a, mut jacobian_b) = (DMatrix::zeros(model.nv(), model.nv()), DMatrix::zeros(model.nv(), model.nv()));
    let count = allocations_during(|| {
        forward_kinematics(&model, &mut data, &q);
        rnea(&model, &mut data, &q, &v, &tau, None);
        aba(&model, &mut data, &q, &v, &tau, None);
        crba(&model, &mut data, &q);
        minv(&model, &mut data, &q);
        jacobian(&model, &mut data, &q, 17, &Vector3::new(0.1, 0.0, 0.0), Frame::LocalWorldAligned);
        center_of_mass(&model, &mut data, &q);
        center_of_mass_jacobian(&model, &mut data, &q);
        subtree_mass_properties(&model, &mut data, &q);
        centroidal_momentum(&model, &mut data, &q, &v);
        centroidal_map(&model, &mut data, &q);
        centroidal_momentum_rate(&model, &mut data, &q, &v, &tau);
        kinetic_energy(&model, &mut data, &q, &v);
        potential_energy(&model, &mut data, &q);
        rnea_derivatives(&model, &mut data, &q, &v, &tau, None);
        rnea_second_order_derivatives(&model, &mut data, &q, &v, &tau);
        aba_derivatives(&model, &mut data, &q, &v, &tau, None);
        let point = Vector3::new(0.1, 0.0, 0.0);
        frame_velocity(&model, &mut data, &q, &v, 17, &point, Frame::World);
        frame_acceleration(&model, &mut data, &q, &v, &tau, 17, &point, Frame::Local);
        frame_velocity_derivatives(&model, &mut data, &q, &v, 17, &point, Frame::LocalWorldAligned);
        frame_acceleration_derivatives(&model, &mut data, &q, &v, &tau, 17, &point, Frame::World);
        jacobian_time_variation(&model, &mut data, &q, &v, 17, &point, Frame::Local);
        centroidal_derivatives(&model, &mut data, &q, &v, &tau);
        integrate(&model, &q, &v, 0.1, &mut q1);
        difference(&model, &q, &q1, &mut dv);
        integrate_jacobians(&model, &v, 0.1, &mut jacobian_a, &mut jacobian_b);
        difference_jacobians(&model, &q, &q1, &mut jacobian_a, &mut jacobian_b);
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
