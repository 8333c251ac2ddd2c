//! Tests of the MJCF loader: nesting and include limits, orientations, joints, free bodies, replicates, classes.

use nalgebra::Vector3;

use super::reader::z_to;
use super::{load_mjcf, JointKind, Mjcf, MjcfOptions, MAX_DEPTH};
use crate::{Error, Joint, Transform};

fn load(xml: &str) -> Mjcf {
    load_mjcf(xml, &MjcfOptions::default()).unwrap()
}

#[test]
fn elements_nested_deeper_than_max_depth_are_refused_before_the_passes_recurse() {
    let nested = |depth: usize| format!("<mujoco><worldbody>{}{}</worldbody></mujoco>", "<body>".repeat(depth), "</body>".repeat(depth));
    // A debug build's frames are larger than a release build's: a stack to match.
    let run = |xml: String| {
        std::thread::Builder::new().stack_size(64 << 20).spawn(move || load_mjcf(&xml, &MjcfOptions::default())).unwrap().join().unwrap()
    };
    // The worldbody is at depth 1, its bodies below it.
    assert_eq!(run(nested(MAX_DEPTH - 1)).unwrap().model.nbodies(), MAX_DEPTH);
    for depth in [MAX_DEPTH, 100 * MAX_DEPTH] {
        let error = run(nested(depth)).unwrap_err();
        assert!(error.to_string().contains("nest deeper than 1000 levels (<string>:1)"), "{error}");
    }
}

#[test]
fn springdamper_is_a_warning_and_leaves_the_damping_read() {
    let xml = "<mujoco><default><joint damping='0.3'/></default><worldbody><body><joint name='h' springdamper='0.1 1'/><geom size='.1'/></body></worldbody></mujoco>";
    let loaded = load(xml);
    assert_eq!(loaded.model.damping(), &[0.3]);
    assert!(
        loaded.warnings.iter().any(|w| w.contains("joint \"h\": springdamper=[0.1, 1.0] is not modelled (its damping=0.3 applies)")),
        "{:?}",
        loaded.warnings
    );
    assert!(load_mjcf(xml, &MjcfOptions { strict: true, ..MjcfOptions::default() }).is_err());
}

#[test]
fn z_to_takes_z_to_the_vector_and_minus_z_by_half_a_turn_about_x() {
    for v in [Vector3::new(0.2, -0.3, 0.9), Vector3::new(-1.0, 0.0, 0.0), Vector3::z(), -Vector3::z()] {
        let q = z_to(v).unwrap();
        assert!((q * Vector3::z() - v.normalize()).norm() < 1e-14, "{v:?}");
    }
    assert!((z_to(-Vector3::z()).unwrap() * Vector3::y() + Vector3::y()).norm() < 1e-14);
    assert!(z_to(Vector3::zeros()).is_none());
}

#[test]
fn euler_lower_case_turns_about_moving_axes_upper_case_about_fixed_ones() {
    let pose = |seq: &str| {
        let xml = format!("<mujoco><compiler angle='radian' eulerseq='{seq}'/><worldbody><body name='b' euler='0.3 0.5 0.7'/></worldbody></mujoco>");
        *load(&xml).model.placement(1)
    };
    let r = |axis: Vector3<f64>, a: f64| Transform::rotation_about(&axis, a);
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    assert!((pose("xyz").rotation - r(x, 0.3) * r(y, 0.5) * r(z, 0.7)).norm() < 1e-14);
    assert!((pose("XYZ").rotation - r(z, 0.7) * r(y, 0.5) * r(x, 0.3)).norm() < 1e-14);
}

#[test]
fn a_hinge_with_an_anchor_and_a_reference_turns_about_the_anchor_with_q_as_mujocos_qpos() {
    let xml = "<mujoco><compiler angle='radian'/><worldbody><body name='b' pos='1 0 0'>
            <joint name='j' pos='0 0 0.5' axis='0 1 0' ref='0.25' range='-1 1'/><geom size='0.1' pos='0 0 0.5'/></body></worldbody></mujoco>";
    let mjcf = load(xml);
    let model = &mjcf.model;
    // The legkit frame sits at the anchor, turned by -ref; the sphere's centre is the anchor.
    let placement = model.placement(1);
    assert!((placement.translation - Vector3::new(1.0, 0.0, 0.5)).norm() < 1e-15);
    assert!((placement.rotation - Transform::rotation_about(&Vector3::y(), -0.25)).norm() < 1e-15);
    assert!(model.body(1).com().norm() < 1e-15);
    assert_eq!((model.limits(1).lower, model.limits(1).upper), (-1.0, 1.0));
    assert_eq!(mjcf.joints[0].idx_q, 0);
}

#[test]
fn a_ball_joint_is_spherical_about_its_anchor_and_ignores_ref() {
    let xml =
        "<mujoco><worldbody><body pos='0 0 1'><joint name='s' type='ball' pos='0 0 0.5' ref='30'/><geom size='.1'/></body></worldbody></mujoco>";
    let loaded = load_mjcf(xml, &MjcfOptions::default()).unwrap();
    let model = &loaded.model;
    assert_eq!((*model.joint(1), model.nq(), model.nv()), (Joint::Spherical, 4, 3));
    assert_eq!(model.placement(1).translation, Vector3::new(0.0, 0.0, 1.5));
    assert_eq!(loaded.joints[0].kind, JointKind::Ball);
}

#[test]
fn several_free_bodies_move_on_slides_and_a_ball_under_a_fixed_world() {
    let xml = "<mujoco><worldbody><body name='a' pos='0 0 1'><freejoint/><geom size='.1'/><body name='c'><joint axis='1 0 0'/><geom size='.1' pos='0 0 .3'/></body></body>
            <body name='b' pos='1 0 1'><joint name='f' type='free' damping='0.5'/><geom size='.2'/></body></worldbody></mujoco>";
    let loaded = load(xml);
    let model = &loaded.model;
    assert!(!model.floating_base());
    assert_eq!((model.nq(), model.nv()), (15, 13));
    let kinds: Vec<_> = (1..model.nbodies()).map(|i| model.joint(i).kind()).collect();
    assert_eq!(kinds, ["prismatic", "prismatic", "prismatic", "spherical", "revolute", "prismatic", "prismatic", "prismatic", "spherical"]);
    assert_eq!((loaded.joints[2].name.as_str(), loaded.joints[2].idx_q, loaded.joints[2].idx_v), ("f", 8, 7));
    assert_eq!(&model.damping()[7..13], &[0.5; 6]);
    assert!(load_mjcf(xml, &MjcfOptions { floating_base: Some(false), strict: false }).unwrap().model.nv() == 1);
}

#[test]
fn replicate_copies_are_named_and_placed_as_mujoco_places_them() {
    let xml = "<mujoco><compiler angle='radian'/><worldbody><replicate count='2' sep='-'>
            <replicate count='10' offset='1 0 0' euler='0 0 1.5707963267948966'><body name='b'><joint/></body></replicate>
            </replicate></worldbody></mujoco>";
    let model = load(xml).model;
    assert_eq!(model.nbodies(), 21);
    assert_eq!((model.name(1), model.name(10), model.name(11), model.name(20)), ("b00-0", "b09-0", "b00-1", "b09-1"));
    // Copy i is turned by i quarter turns and sits at the sum of the offsets turned by the copies before it.
    let expected = [Vector3::zeros(), Vector3::x(), Vector3::new(1.0, 1.0, 0.0), Vector3::y()];
    for (i, p) in expected.iter().enumerate() {
        assert!((model.placement(i + 1).translation - p).norm() < 1e-15, "{i}");
    }
    assert!((model.placement(2).rotation - Transform::rotation_about(&Vector3::z(), std::f64::consts::FRAC_PI_2)).norm() < 1e-15);
    let nested = "<replicate count='1000'>".repeat(3) + "<body/>" + &"</replicate>".repeat(3);
    let error = load_mjcf(&format!("<mujoco><worldbody>{nested}</worldbody></mujoco>"), &MjcfOptions::default()).unwrap_err();
    assert!(matches!(error, Error::TooLarge { .. }) && error.to_string().contains("count=1000 copies of 2001 elements"), "{error}");
}

#[test]
fn unknown_classes_are_errors_naming_them() {
    let error = load_mjcf("<mujoco><worldbody><body childclass='x'/></worldbody></mujoco>", &MjcfOptions::default());
    assert!(error.unwrap_err().to_string().contains("unknown childclass \"x\""));
}

#[test]
fn includes_that_include_themselves_are_refused() {
    let folder = std::env::temp_dir().join(format!("legkit-mjcf-{}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    let file = folder.join("loop.xml");
    std::fs::write(&file, "<mujoco><include file='loop.xml'/></mujoco>").unwrap();
    let error = load_mjcf(file.to_str().unwrap(), &MjcfOptions::default()).unwrap_err();
    assert!(error.to_string().contains("include themselves"), "{error}");
    std::fs::remove_dir_all(&folder).unwrap();
}
