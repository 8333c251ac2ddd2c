use nalgebra::{Matrix3, Rotation3, Vector3};

use super::*;

fn moments(mass: f64, com: Vector3<f64>, spread: f64) -> Moments {
    // A point mass at com plus a symmetric spread: P = m c c^T + spread I.
    let second = com * com.transpose() * mass + Matrix3::identity() * spread;
    let mut x = [0.0; 13];
    x[0] = mass;
    x[1..4].copy_from_slice((com * mass).as_slice());
    for i in 0..9 {
        x[4 + i] = second[(i / 3, i % 3)];
    }
    x
}

fn close(a: &Moments, b: &Moments, tolerance: f64) -> bool {
    a.iter().zip(b).all(|(a, b)| (a - b).abs() <= tolerance)
}

#[test]
fn transform_composes_and_inverts() {
    let x = moments(1.3, Vector3::new(0.1, -0.2, 0.3), 0.02);
    let r1 = *Rotation3::from_euler_angles(0.3, -0.7, 1.1).matrix();
    let r2 = *Rotation3::from_euler_angles(-1.2, 0.4, 0.2).matrix();
    let (t1, t2) = (Vector3::new(0.5, 0.1, -0.3), Vector3::new(-0.2, 0.7, 0.4));
    let twice = transform(&r2, &t2, &transform(&r1, &t1, &x));
    let once = transform(&(r2 * r1), &(r2 * t1 + t2), &x);
    assert!(close(&twice, &once, 1e-14), "{twice:?} vs {once:?}");
    let (ri, ti) = inverse(&r1, &t1);
    assert!(close(&transform(&ri, &ti, &transform(&r1, &t1, &x)), &x, 1e-14));
}

/// Two modules, module 0's connector 3 mated to module 1's connector 0: once the network is silent, each
/// agent's estimate beyond that connector is the other module's own moments in its frame.
#[test]
fn two_modules_agree_and_fall_silent() {
    let part = |z: f64| moments(0.1, Vector3::new(0.0, 0.0, z), 1e-4);
    let connector_rotation = [Matrix3::identity(); SLOTS];
    let mut connector_position = [Vector3::zeros(); SLOTS];
    connector_position[3] = Vector3::new(0.0, 0.0, 0.1);
    let spec = ModuleSpec {
        part_moments: [part(0.01), part(0.03), part(0.06), part(0.09)],
        connector_rotation,
        connector_position,
        joint_axes: [0, 2, 0],
        joint_z: [0.0375, 0.05, 0.0625],
    };
    let mut partner = vec![None; 2 * SLOTS];
    partner[3] = Some(SLOTS);
    partner[SLOTS] = Some(3);
    let mate = *Rotation3::from_euler_angles(std::f64::consts::PI, 0.0, 0.0).matrix();
    let ground = vec![GroundContact {
        module: 0,
        block: 0,
        rotation: Matrix3::identity(),
        translation: Vector3::zeros(),
        line_point: Vector3::zeros(),
        line_direction: Vector3::z(),
        priority: 0.0,
    }];
    let angles = [[0.2, -0.4, 0.3], [-0.5, 0.1, 0.6]];
    let mut network = Network::new(spec, partner, vec![mate; 2 * SLOTS], ground, &angles).unwrap();
    let mut rounds = 0;
    while !network.quiescent() {
        network.round();
        rounds += 1;
        assert!(rounds < 10, "the network did not fall silent");
    }
    let sent: u64 = network.sent_by_module().sum();
    network.round();
    assert_eq!(network.sent_by_module().sum::<u64>(), sent, "a silent network sends nothing");
    // Module 1 in module 0's frame: connector 3's frame, the mate rotation, then the inverse of connector 0's.
    let (r0, t0) = network.connector_frame(0, 3);
    let (ri, ti) = network.connector_frame(1, 0);
    let (ri, ti) = inverse(ri, ti);
    let (r, t) = (r0 * mate * ri, r0 * mate * ti + t0);
    let expected = transform(&r, &t, network.own(1));
    assert!(close(network.estimate(0, 3), &expected, 1e-15), "{:?} vs {expected:?}", network.estimate(0, 3));
    let (ri, ti) = inverse(&r, &t);
    assert!(close(network.estimate(1, 0), &transform(&ri, &ti, network.own(0)), 1e-15));
    // The follower knows the leader and its pose: its module frame's world pose is (r, t).
    assert_eq!(network.fixed_block(1), Some(0));
    let (rotation, translation) = network.world_pose(1);
    assert!((rotation - r).amax() < 1e-15 && (translation - t).amax() < 1e-15);
}
