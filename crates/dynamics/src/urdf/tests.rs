//! Tests of the URDF loader: placements, inertials and numbering against brute-force references, limits, damping,
//! collision shapes and meshes, and the errors and warnings of malformed files.

use super::read::rpy_to_matrix;
use super::*;
use crate::geometry::{Shape, ShapeKind};
use crate::mass::tests::brute_force;
use crate::{Joint, JointLimits, Transform};
use nalgebra::{Matrix3, Rotation3, Unit, Vector3};
use std::f64::consts::FRAC_PI_2;

const FIXED: &UrdfOptions = &UrdfOptions { floating_base: false, strict: false, package_dirs: Vec::new() };
const FLOATING: &UrdfOptions = &UrdfOptions { floating_base: true, strict: false, package_dirs: Vec::new() };

const TOL: f64 = 1e-12;

fn close(a: &Matrix3<f64>, b: &Matrix3<f64>, tol: f64) -> bool {
    (a - b).amax() <= tol
}

fn close3(a: &Vector3<f64>, b: &Vector3<f64>, tol: f64) -> bool {
    (a - b).amax() <= tol
}

/// Independent of `rpy_to_matrix`: nalgebra's Euler angles, checked against URDF's convention below.
fn expected_placement(xyz: [f64; 3], rpy: [f64; 3]) -> Transform {
    Transform::new(Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner(), Vector3::new(xyz[0], xyz[1], xyz[2]))
}

fn assert_placement(model: &Model, body: usize, expected: &Transform) {
    let p = model.placement(body);
    assert!(close(&p.rotation, &expected.rotation, TOL), "body {body}: {:?} vs {:?}", p.rotation, expected.rotation);
    assert!(close3(&p.translation, &expected.translation, TOL), "body {body}: {:?}", p.translation);
}

fn inertia_attrs(i: &Matrix3<f64>) -> String {
    format!(r#"ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}""#, i[(0, 0)], i[(0, 1)], i[(0, 2)], i[(1, 1)], i[(1, 2)], i[(2, 2)])
}

#[test]
fn nalgebra_euler_angles_and_rpy_to_matrix_follow_urdfs_fixed_axis_convention() {
    // URDF: roll about the fixed x, then pitch about the fixed y, then yaw about the fixed z, so
    // R = Rz(yaw) Ry(pitch) Rx(roll). nalgebra documents from_euler_angles as "roll, then pitch, then
    // yaw" about fixed axes; check both against the product of elementary rotations.
    let about = |axis: Vector3<f64>, angle: f64| Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle);
    for &(r, p, y) in &[(0.3, -0.7, 1.1), (-1.2, 0.4, 2.5), (2.9, 1.4, -3.0), (0.0, 0.0, 0.0)] {
        let product = (about(Vector3::z(), y) * about(Vector3::y(), p) * about(Vector3::x(), r)).into_inner();
        assert!(close(&Rotation3::from_euler_angles(r, p, y).into_inner(), &product, TOL));
        assert!(close(&rpy_to_matrix(r, p, y), &product, TOL));
    }
    // Concrete cases that tell the conventions apart: yaw takes x to y, roll takes y to z, and roll
    // then pitch (fixed axes) takes y to z and then z to x; the moving-axis Rx Ry would give z.
    assert!(close3(&(rpy_to_matrix(0.0, 0.0, FRAC_PI_2) * Vector3::x()), &Vector3::y(), TOL));
    assert!(close3(&(rpy_to_matrix(FRAC_PI_2, 0.0, 0.0) * Vector3::y()), &Vector3::z(), TOL));
    assert!(close3(&(rpy_to_matrix(FRAC_PI_2, FRAC_PI_2, 0.0) * Vector3::y()), &Vector3::x(), TOL));
}

fn pendulum_xml() -> (String, Vector3<f64>, Matrix3<f64>, Matrix3<f64>, f64) {
    // The upper link's body is a cloud of point masses given in its inertial frame (COM at the origin).
    let masses = [1.0, 2.0, 0.5, 1.5];
    let raw = [Vector3::new(0.3, 0.1, -0.2), Vector3::new(-0.1, 0.4, 0.05), Vector3::new(0.2, -0.3, 0.6), Vector3::new(-0.25, -0.1, -0.3)];
    let (_, c, _) = brute_force(&masses, &raw);
    let points: Vec<Vector3<f64>> = raw.iter().map(|p| p - c).collect();
    let (_, _, inertia_local) = brute_force(&masses, &points);
    let mass: f64 = masses.iter().sum();
    // Brute force in the link frame: move every point by the inertial origin and recompute.
    let (rpy, xyz) = ([0.3, -0.7, 1.1], Vector3::new(0.1, -0.2, 0.3));
    let rot = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner();
    let moved: Vec<Vector3<f64>> = points.iter().map(|p| rot * p + xyz).collect();
    let (_, com_link, inertia_link) = brute_force(&masses, &moved);
    let xml = format!(
        r#"<?xml version="1.0"?>
            <robot name="pendulum">
              <link name="base">
                <inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
              </link>
              <link name="upper">
                <visual><geometry><box size="0.1 0.1 1"/></geometry></visual>
                <inertial>
                  <origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.7 1.1"/>
                  <mass value="{mass}"/>
                  <inertia {attrs}/>
                </inertial>
              </link>
              <link name="lower">
                <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.025"/></inertial>
              </link>
              <joint name="shoulder" type="revolute">
                <parent link="base"/><child link="upper"/>
                <origin xyz="0 0 1" rpy="0.1 0.2 0.3"/>
                <axis xyz="0 2 0"/>
                <limit lower="-1" upper="1" effort="10" velocity="1"/>
              </joint>
              <joint name="elbow" type="continuous">
                <parent link="upper"/><child link="lower"/>
                <origin xyz="0.5 0 -0.25" rpy="-1.2 0.4 2.5"/>
                <axis xyz="1 1 0"/>
              </joint>
            </robot>"#,
        attrs = inertia_attrs(&inertia_local)
    );
    (xml, com_link, inertia_link, inertia_local, mass)
}

#[test]
fn two_link_pendulum_structure_placements_axes_and_inertials() {
    let (xml, com_link, inertia_link, inertia_local, mass) = pendulum_xml();
    let model = parse_urdf(&xml, FIXED).unwrap().model;
    assert_eq!(model.nbodies(), 3);
    assert_eq!((model.nq(), model.nv()), (2, 2));
    assert!(!model.floating_base());
    assert_eq!([model.name(0), model.name(1), model.name(2)], ["base", "upper", "lower"]);
    assert_eq!([model.parent(1), model.parent(2)], [0, 1]);
    assert_eq!(*model.joint(0), Joint::Fixed);

    assert_placement(&model, 0, &Transform::identity());
    assert_placement(&model, 1, &expected_placement([0.0, 0.0, 1.0], [0.1, 0.2, 0.3]));
    assert_placement(&model, 2, &expected_placement([0.5, 0.0, -0.25], [-1.2, 0.4, 2.5]));

    // Axes are normalised.
    let Joint::Revolute(a1) = *model.joint(1) else { panic!("{:?}", model.joint(1)) };
    assert!(close3(&a1, &Vector3::new(0.0, 1.0, 0.0), TOL));
    let Joint::Revolute(a2) = *model.joint(2) else { panic!("{:?}", model.joint(2)) };
    let s = 0.5f64.sqrt();
    assert!(close3(&a2, &Vector3::new(s, s, 0.0), TOL));

    // The rotated, offset inertial agrees with the brute force over the moved point cloud.
    let upper = model.body(1);
    assert!((upper.mass() - mass).abs() < TOL);
    assert!(close3(&upper.com(), &com_link, 1e-12));
    assert!(close(&upper.inertia(), &inertia_link, 1e-12), "{:?} vs {:?}", upper.inertia(), inertia_link);
    // and it really was rotated: the inertia in the inertial frame is far from it.
    assert!(!close(&upper.inertia(), &inertia_local, 1e-2));

    // No <origin> in <inertial>: the inertia is taken as is, the COM at the link origin.
    let lower = model.body(2);
    assert_eq!(lower.mass(), 1.0);
    assert_eq!(lower.com(), Vector3::zeros());
    assert_eq!(lower.inertia(), Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.025)));
    assert_eq!(model.body(0).mass(), 2.0);
    assert!((model.total_mass() - (3.0 + mass)).abs() < TOL);
}

#[test]
fn branching_tree_listed_in_scrambled_order_is_numbered_parent_before_child() {
    let legs = ["FL", "FR", "RL", "RR"];
    let chain = ["hip", "thigh", "calf", "foot"];
    let mut links = vec!["trunk".to_owned(), "imu".to_owned()];
    // (joint name, type, parent link, child link)
    let mut joints = vec![("imu_joint".to_owned(), "fixed", "trunk".to_owned(), "imu".to_owned())];
    for leg in legs {
        let mut parent = "trunk".to_owned();
        for (k, part) in chain.iter().enumerate() {
            let child = format!("{leg}_{part}");
            let kind = if k == 3 { "fixed" } else { "revolute" };
            joints.push((format!("{leg}_{part}_joint"), kind, parent.clone(), child.clone()));
            links.push(child.clone());
            parent = child;
        }
    }
    let expected_parent: HashMap<String, String> = joints.iter().map(|(_, _, parent, child)| (child.clone(), parent.clone())).collect();
    // Scramble: links and joints deepest first, interleaved, with the root link in the middle.
    links.reverse();
    links.rotate_left(7);
    joints.reverse();
    let mut body = String::new();
    for k in 0..links.len().max(joints.len()) {
        if let Some((name, kind, parent, child)) = joints.get(k) {
            body += &format!(
                r#"<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>
                       <origin xyz="0.1 0.2 -0.3" rpy="0.1 0 0"/><axis xyz="0 1 0"/></joint>"#
            );
        }
        if let Some(name) = links.get(k) {
            body += &format!(
                r#"<link name="{name}"><inertial><mass value="0.5"/>
                       <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>"#
            );
        }
    }
    let xml = format!("<robot name=\"dog\">{body}</robot>");
    // The scramble did put children before parents in the file.
    assert!(xml.find("name=\"FL_foot\"").unwrap() < xml.find("name=\"FL_hip\"").unwrap());
    assert!(xml.find("name=\"FL_foot_joint\"").unwrap() < xml.find("name=\"FL_hip_joint\"").unwrap());

    for floating in [false, true] {
        let model = parse_urdf(&xml, &UrdfOptions { floating_base: floating, ..Default::default() }).unwrap().model;
        assert_eq!(model.nbodies(), 18);
        assert_eq!(model.name(0), "trunk");
        let moving = 12;
        let (nq, nv) = if floating { (7 + moving, 6 + moving) } else { (moving, moving) };
        assert_eq!((model.nq(), model.nv()), (nq, nv));
        for i in 1..model.nbodies() {
            assert!(model.parent(i) < i, "body {i} ({}) has parent {}", model.name(i), model.parent(i));
            assert_eq!(model.name(model.parent(i)), expected_parent[model.name(i)], "body {}", model.name(i));
        }
        let mut names: Vec<&str> = (0..model.nbodies()).map(|i| model.name(i)).collect();
        names.sort_unstable();
        let mut all: Vec<&str> = links.iter().map(String::as_str).collect();
        all.sort_unstable();
        assert_eq!(names, all);
    }
}

#[test]
fn joints_are_numbered_as_pinocchio_numbers_them_depth_first_siblings_by_joint_name() {
    // (joint, parent link, child link, type) in file order; sibling joints out of name order, a fixed joint
    // with a moving child, and names where byte order differs from case-blind order ("Z_h" < "a_c").
    let joints = [
        ("z_b", "root", "B", "revolute"),
        ("a_c", "root", "C", "revolute"),
        ("m_d", "B", "D", "revolute"),
        ("b_e", "C", "E", "revolute"),
        ("f_f", "root", "F", "fixed"),
        ("c_g", "F", "G", "revolute"),
        ("Z_h", "root", "H", "revolute"),
    ];
    let mut body: String = ["G", "root", "B", "C", "D", "E", "F", "H"].iter().map(|l| format!(r#"<link name="{l}"/>"#)).collect();
    for (name, parent, child, kind) in joints {
        body += &format!(r#"<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/><axis xyz="0 0 1"/></joint>"#);
    }
    let xml = format!("<robot name=\"order\">{body}</robot>");
    for floating in [false, true] {
        let model = parse_urdf(&xml, &UrdfOptions { floating_base: floating, ..Default::default() }).unwrap().model;
        // What pin.buildModelFromUrdf gives for this file (model.names[1:], and the bodies of model.frames).
        let joint_names: Vec<&str> = (0..model.nbodies()).map(|i| model.joint_name(i)).collect();
        assert_eq!(joint_names, [crate::ROOT_JOINT, "Z_h", "a_c", "b_e", "f_f", "c_g", "z_b", "m_d"]);
        let body_names: Vec<&str> = (0..model.nbodies()).map(|i| model.name(i)).collect();
        assert_eq!(body_names, ["root", "H", "C", "E", "F", "G", "B", "D"]);
        for (i, name) in joint_names.iter().enumerate() {
            assert_eq!(model.joint_index(name), Some(i));
        }
        assert_eq!(model.joint_index("B"), None);
    }
}

#[test]
fn fixed_continuous_and_prismatic_joints_and_floating_base() {
    let xml = r#"
            <robot name="mixed">
              <link name="root"><inertial><mass value="3"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
              <link name="bracket"/>
              <link name="wheel"><inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
              <link name="slider"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
              <link name="tip"><inertial><origin xyz="0 0 0.2"/><mass value="0.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
              <joint name="mount" type="fixed">
                <parent link="root"/><child link="bracket"/><origin xyz="0 0 0.5"/><axis xyz="0 0 0"/>
              </joint>
              <joint name="spin" type="continuous"><parent link="bracket"/><child link="wheel"/></joint>
              <joint name="slide" type="prismatic">
                <parent link="wheel"/><child link="slider"/><origin rpy="0 0 1.5707963267948966"/><axis xyz="0 0 -3"/>
              </joint>
              <joint name="twist" type="revolute"><parent link="slider"/><child link="tip"/><axis xyz="0 0 1"/></joint>
              <transmission name="t"><joint name="spin"/><actuator name="m"/></transmission>
            </robot>"#;
    let model = parse_urdf(xml, FIXED).unwrap().model;
    assert_eq!(model.nbodies(), 5);
    assert_eq!((model.nq(), model.nv()), (3, 3));
    assert_eq!(*model.joint(1), Joint::Fixed);
    // Continuous joint without <axis>: the default x axis; without <origin>: identity.
    assert_eq!(*model.joint(2), Joint::Revolute(Vector3::x()));
    assert_placement(&model, 2, &Transform::identity());
    let Joint::Prismatic(axis) = *model.joint(3) else { panic!("{:?}", model.joint(3)) };
    assert!(close3(&axis, &-Vector3::z(), TOL));
    assert_placement(&model, 3, &expected_placement([0.0; 3], [0.0, 0.0, FRAC_PI_2]));
    assert_eq!(*model.joint(4), Joint::Revolute(Vector3::z()));
    assert_placement(&model, 1, &expected_placement([0.0, 0.0, 0.5], [0.0; 3]));
    // Massless links: no <inertial>, or mass 0.
    assert!(model.body(1).is_zero() && model.body(2).is_zero());
    assert_eq!(model.body(4).com(), Vector3::new(0.0, 0.0, 0.2));
    assert_eq!([model.idx_q(2), model.idx_q(3), model.idx_q(4)], [0, 1, 2]);

    let floating = parse_urdf(xml, FLOATING).unwrap().model;
    assert!(floating.floating_base());
    assert_eq!(*floating.joint(0), Joint::FreeFlyer);
    assert_eq!((floating.nq(), floating.nv()), (7 + 3, 6 + 3));
    assert_eq!(floating.nbodies(), 5);
    assert_eq!(floating.name(0), "root");
}

#[test]
fn a_cancelled_load_stops_and_an_uncancelled_one_is_unchanged() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let links: String = (1..3000)
        .map(|i| format!(r#"<link name="l{i}"/><joint name="j{i}" type="fixed"><parent link="l{}"/><child link="l{i}"/></joint>"#, i - 1))
        .collect();
    let xml = format!(r#"<robot name="r"><link name="l0"/>{links}</robot>"#);
    let flag = Arc::new(AtomicBool::new(false));
    let loaded = crate::validate::cancellable(Arc::clone(&flag), || parse_urdf(&xml, FIXED)).unwrap();
    assert_eq!(loaded.model.nbodies(), 3000);
    flag.store(true, Ordering::Relaxed);
    let error = crate::validate::cancellable(Arc::clone(&flag), || parse_urdf(&xml, FIXED)).unwrap_err();
    assert!(error.to_string().contains("cancelled"), "{error}");
    // Outside `cancellable` the flag is not this thread's.
    assert_eq!(parse_urdf(&xml, FIXED).unwrap().model.nbodies(), 3000);
}

#[test]
fn load_urdf_reads_files_and_inline_xml() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/two_link_pendulum.urdf");
    let from_file = load_urdf(path, FIXED).unwrap().model;
    let text = std::fs::read_to_string(path).unwrap();
    let inline = load_urdf(&format!("\n  {text}"), FIXED).unwrap().model;
    assert_eq!(from_file.nbodies(), 3);
    assert_eq!((from_file.nq(), from_file.nv()), (2, 2));
    assert_eq!(from_file.name(2), "forearm");
    assert_placement(&from_file, 2, &Transform::from_translation(Vector3::new(0.0, 0.0, -1.0)));
    assert_eq!(from_file.body(2).com(), Vector3::new(0.0, 0.0, -0.5));
    for i in 0..3 {
        assert_eq!(from_file.placement(i), inline.placement(i));
        assert_eq!(from_file.body(i), inline.body(i));
        assert_eq!(from_file.name(i), inline.name(i));
    }

    let missing = load_urdf("/nonexistent/robot.urdf", FIXED).unwrap_err();
    assert_eq!(missing.argument(), "path");
    assert!(missing.to_string().contains("/nonexistent/robot.urdf"), "{missing}");
}

/// Parses `xml`, expecting an error on argument "urdf" whose message contains every one of `needles`.
fn assert_fails(xml: &str, needles: &[&str]) {
    let error = match parse_urdf(xml, &UrdfOptions { strict: true, ..Default::default() }) {
        Ok(urdf) => panic!("expected an error containing {needles:?}, got a model with {} bodies", urdf.model.nbodies()),
        Err(e) => e,
    };
    assert_eq!(error.argument(), "urdf");
    let message = error.to_string();
    for needle in needles {
        assert!(message.contains(needle), "{message:?} does not contain {needle:?}");
    }
}

const INERTIA: &str = r#"<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>"#;

/// A robot with links `a` and `b` joined by revolute `j`, plus `extra`.
fn robot(extra: &str) -> String {
    format!(
        r#"<robot name="r"><link name="a"/><link name="b"/>
               <joint name="j" type="revolute"><parent link="a"/><child link="b"/></joint>{extra}</robot>"#
    )
}

/// A robot whose only link `heavy` has the given inertial contents.
fn inertial_robot(inertial: &str) -> String {
    format!(r#"<robot name="r"><link name="heavy"><inertial>{inertial}</inertial></link></robot>"#)
}

fn joint_robot(joint: &str) -> String {
    format!(r#"<robot name="r"><link name="a"/><link name="b"/>{joint}</robot>"#)
}

#[test]
fn the_helpers_build_valid_robots() {
    // So that each error below is due to its one defect.
    assert_eq!(parse_urdf(&robot(""), FIXED).unwrap().model.nbodies(), 2);
    let ok = inertial_robot(&format!(r#"<mass value="1"/>{INERTIA}"#));
    assert_eq!(parse_urdf(&ok, FIXED).unwrap().model.body(0).mass(), 1.0);
    let ok = joint_robot(r#"<joint name="j" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>"#);
    assert_eq!(parse_urdf(&ok, FIXED).unwrap().model.nv(), 1);
}

#[test]
fn malformed_documents_are_errors() {
    assert_fails("not xml at all", &["not valid XML"]);
    assert_fails("<robot name=\"r\"><link name=\"a\">", &["not valid XML"]);
    assert_fails(r#"<model name="m"><link name="a"/></model>"#, &["<robot>", "<model>"]);
    assert_fails(r#"<robot name="r"/>"#, &["no <link>"]);
    assert_fails(r#"<robot name="r"><link/></robot>"#, &["<link> has no name", "line 1"]);
    // Blank lines before an XML declaration are tolerated and counted.
    assert_fails("\n\n<?xml version=\"1.0\"?>\n<robot name=\"r\">\n<link/></robot>", &["no name", "line 5"]);
    assert_fails(&robot(r#"<joint type="fixed"><parent link="a"/><child link="b"/></joint>"#), &["<joint> has no name"]);
}

#[test]
fn duplicate_and_unknown_names_are_errors() {
    assert_fails(&robot(r#"<link name="a"/>"#), &[r#"link "a" is defined twice"#]);
    assert_fails(
        &robot(r#"<link name="c"/><joint name="j" type="fixed"><parent link="b"/><child link="c"/></joint>"#),
        &[r#"joint "j" is defined twice"#],
    );
    assert_fails(
        &joint_robot(r#"<joint name="knee" type="revolute"><parent link="thigh2"/><child link="b"/></joint>"#),
        &[r#"joint "knee": unknown parent link "thigh2""#],
    );
    assert_fails(
        &joint_robot(r#"<joint name="knee" type="revolute"><parent link="a"/><child link="shin"/></joint>"#),
        &[r#"joint "knee": unknown child link "shin""#],
    );
    assert_fails(&joint_robot(r#"<joint name="knee" type="revolute"><child link="b"/></joint>"#), &[r#"joint "knee": missing <parent"#]);
    assert_fails(&joint_robot(r#"<joint name="knee" type="revolute"><parent link="a"/><child/></joint>"#), &[r#"joint "knee": missing <child"#]);
}

#[test]
fn non_tree_structures_are_errors() {
    // A link with two parents.
    assert_fails(
        &robot(
            r#"<link name="c"/><joint name="j1" type="fixed"><parent link="a"/><child link="c"/></joint>
                      <joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint>"#,
        ),
        &[r#"link "c" has two parents"#, r#""j1""#, r#""j2""#],
    );
    // A cycle beside a proper root.
    assert_fails(
        r#"<robot name="r"><link name="root"/><link name="x"/><link name="y"/>
               <joint name="j1" type="fixed"><parent link="x"/><child link="y"/></joint>
               <joint name="j2" type="fixed"><parent link="y"/><child link="x"/></joint></robot>"#,
        &["cycle", r#""x" -> "y" -> "x""#],
    );
    // A joint from a link to itself.
    assert_fails(
        r#"<robot name="r"><link name="root"/><link name="x"/>
               <joint name="j" type="fixed"><parent link="x"/><child link="x"/></joint></robot>"#,
        &["cycle", r#""x" -> "x""#],
    );
    // No root at all.
    assert_fails(
        r#"<robot name="r"><link name="x"/><link name="y"/>
               <joint name="j1" type="fixed"><parent link="x"/><child link="y"/></joint>
               <joint name="j2" type="fixed"><parent link="y"/><child link="x"/></joint></robot>"#,
        &["no root link", "cycle", r#""x""#, r#""y""#],
    );
    // Two roots.
    assert_fails(&robot(r#"<link name="island"/>"#), &["more than one root link", r#""a""#, r#""island""#]);
}

#[test]
fn bad_inertials_are_errors_naming_the_link() {
    let link = r#"link "heavy""#;
    assert_fails(&inertial_robot(&format!(r#"<mass value="-1"/>{INERTIA}"#)), &[link, "mass must be >= 0"]);
    assert_fails(&inertial_robot(&format!(r#"<mass value="nan"/>{INERTIA}"#)), &[link, "not finite"]);
    assert_fails(&inertial_robot(&format!(r#"<mass value="inf"/>{INERTIA}"#)), &[link, "not finite"]);
    assert_fails(&inertial_robot(&format!(r#"<mass value="heavy"/>{INERTIA}"#)), &[link, "not a number"]);
    assert_fails(&inertial_robot(&format!(r#"<mass value="1 2"/>{INERTIA}"#)), &[link, "expected 1 number"]);
    assert_fails(&inertial_robot(&format!(r#"<mass/>{INERTIA}"#)), &[link, "no value attribute"]);
    assert_fails(&inertial_robot(INERTIA), &[link, "no <mass>"]);
    assert_fails(&inertial_robot(r#"<mass value="1"/>"#), &[link, "no <inertia>"]);
    // Principal moments 1, 1, 3 violate the triangle inequality.
    let triangle = r#"<mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"/>"#;
    assert_fails(&inertial_robot(triangle), &[link, "non-physical", "inertia"]);
    let negative = r#"<mass value="1"/><inertia ixx="-1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>"#;
    assert_fails(&inertial_robot(negative), &[link, "non-physical"]);
    let unparsable = r#"<mass value="1"/><inertia ixx="abc" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>"#;
    assert_fails(&inertial_robot(unparsable), &[link, "ixx", "not a number"]);
    let missing = r#"<mass value="1"/><inertia ixx="1" ixz="0" iyy="1" iyz="0" izz="1"/>"#;
    assert_fails(&inertial_robot(missing), &[link, "no ixy attribute"]);
    let short_rpy = format!(r#"<origin rpy="0 1"/><mass value="1"/>{INERTIA}"#);
    assert_fails(&inertial_robot(&short_rpy), &[link, "rpy", "expected 3 numbers, found 2"]);
}

#[test]
fn limits_are_read_per_joint_type() {
    let (xml, ..) = pendulum_xml();
    let model = parse_urdf(&xml, FIXED).unwrap().model;
    assert_eq!(*model.limits(0), JointLimits::NONE);
    assert_eq!(*model.limits(1), JointLimits { lower: -1.0, upper: 1.0, effort: 10.0, velocity: 1.0 });
    // "elbow" is continuous without <limit>.
    assert_eq!(*model.limits(2), JointLimits::NONE);
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/two_link_pendulum.urdf");
    let fixture = load_urdf(path, FIXED).unwrap().model;
    assert_eq!(*fixture.limits(2), JointLimits { lower: -2.5, upper: 2.5, effort: 10.0, velocity: 5.0 });

    let joint = |kind: &str, limit: &str| {
        let xml = joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/>{limit}</joint>"#));
        *parse_urdf(&xml, FIXED).unwrap().model.limits(1)
    };
    let inf = f64::INFINITY;
    // A continuous joint keeps effort and velocity but has no position range, whatever it says.
    assert_eq!(
        joint("continuous", r#"<limit lower="-1" upper="1" effort="5" velocity="2"/>"#),
        JointLimits { lower: -inf, upper: inf, effort: 5.0, velocity: 2.0 }
    );
    // lower and upper default to 0 (URDF specification); effort and velocity to no bound.
    assert_eq!(joint("revolute", r#"<limit effort="3"/>"#), JointLimits { lower: 0.0, upper: 0.0, effort: 3.0, velocity: inf });
    assert_eq!(joint("prismatic", r#"<limit upper="0.25" velocity="0.5"/>"#), JointLimits { lower: 0.0, upper: 0.25, effort: inf, velocity: 0.5 });
    assert_eq!(joint("revolute", ""), JointLimits::NONE);
    // Limits on a fixed joint mean nothing and are ignored.
    assert_eq!(joint("fixed", r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#), JointLimits::NONE);
}

#[test]
fn dynamics_damping_is_read_per_moving_joint() {
    let damping = |kind: &str, dynamics: &str| {
        let xml = joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/>{dynamics}</joint>"#));
        parse_urdf(&xml, FIXED).map(|urdf| urdf.model.damping().to_vec())
    };
    assert_eq!(damping("revolute", r#"<dynamics damping="0.25" friction="0.2"/>"#).unwrap(), vec![0.25]);
    assert_eq!(damping("prismatic", r#"<dynamics friction="0.2"/>"#).unwrap(), vec![0.0]);
    assert_eq!(damping("fixed", r#"<dynamics damping="0.25"/>"#).unwrap(), Vec::<f64>::new());
    assert_eq!(damping("spherical", r#"<dynamics damping="0.25"/>"#).unwrap(), vec![0.25; 3]);
    assert_eq!(damping("floating", r#"<dynamics damping="0.5"/>"#).unwrap(), vec![0.5; 6]);
    let error = damping("spherical", r#"<dynamics damping="-1"/>"#).unwrap_err().to_string();
    assert!(error.contains("damping> must be >= 0"), "{error}");
    let knee = r#"joint "knee""#;
    let error = damping("revolute", r#"<dynamics damping="-1"/>"#).unwrap_err().to_string();
    assert!(error.contains(knee) && error.contains("damping> must be >= 0"), "{error}");
    let error = damping("continuous", r#"<dynamics damping="nan"/>"#).unwrap_err().to_string();
    assert!(error.contains(knee), "{error}");
}

#[test]
fn bad_limits_are_errors_naming_the_joint() {
    let joint = |kind: &str, limit: &str| {
        joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/><limit {limit}/></joint>"#))
    };
    let knee = r#"joint "knee""#;
    assert_fails(&joint("revolute", r#"lower="1" upper="-1""#), &[knee, "lower (1) must be <= upper (-1)"]);
    assert_fails(&joint("prismatic", r#"lower="0.5""#), &[knee, "lower (0.5) must be <= upper (0)"]);
    assert_fails(&joint("revolute", r#"lower="-1" upper="1" effort="-1""#), &[knee, "effort must be > 0", "got -1"]);
    assert_fails(&joint("continuous", r#"velocity="-2""#), &[knee, "velocity must be > 0", "got -2"]);
    // What exporters write for "unset": no bound with a warning, an error only when strict.
    assert_fails(&joint("revolute", r#"lower="-1" upper="1" effort="0""#), &[knee, r#"effort="0" read as no bound"#, "strict"]);
    assert_fails(&joint("revolute", r#"lower="low" upper="1""#), &[knee, "lower", r#""low" is not a number"#]);
    assert_fails(&joint("revolute", r#"lower="-1" upper="inf""#), &[knee, "upper", "not finite"]);
    assert_fails(&joint("prismatic", r#"effort="1 2""#), &[knee, "effort", "expected 1 number, found 2"]);
    assert_fails(&joint("revolute", r#"upper="""#), &[knee, "upper", "expected 1 number, found 0"]);
}

#[test]
fn what_exporters_write_loads_as_written_with_warnings() {
    let urdf = |xml: &str| parse_urdf(xml, FIXED).unwrap();
    // effort="0" and velocity="0" mean "unset".
    let unset = urdf(&joint_robot(
        r#"<joint name="knee" type="revolute"><parent link="a"/><child link="b"/><limit lower="-1" upper="1" effort="0" velocity="0"/></joint>"#,
    ));
    assert_eq!(*unset.model.limits(1), JointLimits { lower: -1.0, upper: 1.0, effort: f64::INFINITY, velocity: f64::INFINITY });
    assert_eq!(unset.warnings.len(), 2);
    assert!(unset.warnings.iter().all(|w| w.starts_with(r#"joint "knee": <limit>"#)), "{:?}", unset.warnings);
    // A non-physical inertia (moments 1, 1, 3) is kept as written, turned by the inertial frame.
    let triangle =
        urdf(&inertial_robot(r#"<origin rpy="0 1.5707963267948966 0"/><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"/>"#));
    let body = triangle.model.body(0);
    assert!((body.inertia() - Matrix3::from_diagonal(&Vector3::new(3.0, 1.0, 1.0))).amax() < 1e-12);
    assert_eq!(body.mass(), 2.0);
    assert_eq!(triangle.warnings.len(), 1);
    assert!(triangle.warnings[0].contains(r#"link "heavy": non-physical <inertial>"#) && triangle.warnings[0].contains("kept as written"));
    // Round-off passes silently: a written-out zero inertia with a 1e-35 term (iCub's head), and a
    // principal moment of -2e-22 beside real ones.
    assert!(urdf(&inertial_robot(r#"<mass value="1"/><inertia ixx="0" ixy="0" ixz="2.4e-35" iyy="0" iyz="0" izz="0"/>"#)).warnings.is_empty());
    assert!(urdf(&inertial_robot(r#"<mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="-2e-22"/>"#)).warnings.is_empty());
    // A massless link keeps its rotational inertia, as in Pinocchio.
    let massless = urdf(&inertial_robot(r#"<origin xyz="1 2 3"/><mass value="0"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.3"/>"#));
    let body = massless.model.body(0);
    assert_eq!(body.mass(), 0.0);
    assert!(!body.is_zero());
    assert_eq!(body.inertia(), Matrix3::from_diagonal(&Vector3::new(0.1, 0.2, 0.3)));
    assert!(massless.warnings.is_empty());
}

#[test]
fn collisions_become_the_models_collision_shapes() {
    let xml = r#"<robot name="r">
            <link name="a"><collision><geometry><box size="1 2 3"/></geometry></collision></link>
            <link name="b">
              <inertial><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
              <collision><origin xyz="0 0 -0.5" rpy="1.5707963267948966 0 0"/><geometry><cylinder radius="0.1" length="0.4"/></geometry></collision>
              <collision><origin xyz="0 0 -1"/><geometry><sphere radius="0.02"/></geometry></collision>
              <collision><geometry><capsule radius="0.05" length="0.3"/></geometry></collision>
            </link>
            <link name="c"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
              <collision><geometry><mesh filename="package://r/c.stl"/></geometry></collision></link>
            <link name="d"/>
            <joint name="j" type="revolute"><parent link="a"/><child link="b"/><limit lower="-1" upper="1"/></joint>
            <joint name="k" type="fixed"><parent link="b"/><child link="c"/></joint>
            <joint name="l" type="fixed"><parent link="c"/><child link="d"/></joint>
        </robot>"#;
    let urdf = parse_urdf(xml, FIXED).unwrap();
    let shapes = urdf.model.collision_shapes().unwrap();
    let kinds: Vec<(usize, ShapeKind)> = shapes.iter().map(|(b, s)| (*b, s.kind.clone())).collect();
    assert_eq!(
        kinds,
        vec![
            (0, ShapeKind::Box(Vector3::new(1.0, 2.0, 3.0))),
            (1, ShapeKind::Cylinder { half_height: 0.2, radius: 0.1 }),
            (1, ShapeKind::Sphere(0.02)),
            (1, ShapeKind::Capsule { half_height: 0.15, radius: 0.05 }),
            (2, Shape::default_box(urdf.model.body(2)).unwrap().kind),
        ]
    );
    let (placement, expected) = (shapes[1].1.placement.unwrap(), expected_placement([0.0, 0.0, -0.5], [FRAC_PI_2, 0.0, 0.0]));
    assert!(close(&placement.rotation, &expected.rotation, TOL) && close3(&placement.translation, &expected.translation, TOL));
    assert_eq!(urdf.warnings.len(), 1);
    assert!(urdf.warnings[0].contains(r#"link "c": <collision> meshes not read: "package://r/c.stl" ("#), "{}", urdf.warnings[0]);
    // A robot without any <collision> has no collision shapes (simulations give it default boxes).
    assert!(parse_urdf(&robot(""), FIXED).unwrap().model.collision_shapes().is_none());
    let bad = r#"<robot name="r"><link name="a"><collision><geometry><sphere radius="-1"/></geometry></collision></link></robot>"#;
    assert_fails(bad, &[r#"link "a""#, "<sphere>", "must be > 0"]);
    let unknown = r#"<robot name="r"><link name="a"><collision><geometry><cone radius="1"/></geometry></collision></link></robot>"#;
    assert_fails(unknown, &[r#"link "a""#, "unknown geometry <cone>"]);
}

#[test]
fn collision_meshes_become_convex_hulls_found_by_package_and_relative_names() {
    let root = std::env::temp_dir().join(format!("legkit-urdf-meshes-{}", std::process::id()));
    std::fs::create_dir_all(root.join("bot/meshes")).unwrap();
    std::fs::create_dir_all(root.join("bot/urdf")).unwrap();
    // A unit cube's corners plus its centre (not a hull vertex).
    let corners: Vec<[f64; 3]> = (0..8).map(|k| [(k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64]).collect();
    let obj: String = corners.iter().chain([[0.5, 0.5, 0.5]].iter()).map(|c| format!("v {} {} {}\n", c[0], c[1], c[2])).collect();
    std::fs::write(root.join("bot/meshes/cube.obj"), obj).unwrap();
    let link = |name: &str, filename: &str| {
        format!(r#"<link name="{name}"><collision><geometry><mesh filename="{filename}" scale="0.1 0.2 0.3"/></geometry></collision></link>"#)
    };
    let xml = format!(
        r#"<robot name="r">{}{}{}<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint><joint name="k" type="fixed"><parent link="a"/><child link="c"/></joint></robot>"#,
        link("a", "package://bot/meshes/cube.obj"),
        link("b", "../meshes/cube.obj"),
        link("c", "package://bot/meshes/missing.stl"),
    );
    let path = root.join("bot/urdf/r.urdf");
    std::fs::write(&path, &xml).unwrap();
    let urdf = load_urdf(path.to_str().unwrap(), FIXED).unwrap();
    let shapes = urdf.model.collision_shapes().unwrap();
    for (body, shape) in &shapes[..2] {
        let ShapeKind::Convex(hull) = &shape.kind else { panic!("body {body}: {:?}", shape.kind) };
        assert_eq!(hull.vertices().len(), 8);
        for c in &corners {
            let scaled = Vector3::new(0.1 * c[0], 0.2 * c[1], 0.3 * c[2]);
            assert!(hull.vertices().iter().any(|v| (v - scaled).norm() < 1e-12), "{scaled:?} missing on body {body}");
        }
    }
    // The missing mesh: the inertia box (here none: a massless link) and a warning naming it.
    assert_eq!(shapes.len(), 2);
    assert_eq!(urdf.warnings.len(), 1);
    assert!(
        urdf.warnings[0].contains(r#"link "c""#) && urdf.warnings[0].contains("missing.stl") && urdf.warnings[0].contains("package_dirs"),
        "{}",
        urdf.warnings[0]
    );
    // Parsed from a string, package names still resolve through package_dirs.
    let options = UrdfOptions { package_dirs: vec![root.clone()], ..Default::default() };
    let from_text = parse_urdf(&xml, &options).unwrap();
    assert!(matches!(from_text.model.collision_shapes().unwrap()[0].1.kind, ShapeKind::Convex(_)));
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn bad_joints_are_errors_naming_the_joint() {
    let joint =
        |kind: &str, inner: &str| joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/>{inner}</joint>"#));
    let knee = r#"joint "knee""#;
    assert_fails(&joint("revolute", r#"<origin xyz="1 2"/>"#), &[knee, "xyz", "expected 3 numbers, found 2"]);
    assert_fails(&joint("revolute", r#"<origin xyz="1 2 3 4"/>"#), &[knee, "expected 3 numbers, found 4"]);
    assert_fails(&joint("revolute", r#"<origin xyz="1 2 x"/>"#), &[knee, r#""x" is not a number"#]);
    assert_fails(&joint("revolute", r#"<origin rpy="0 0 inf"/>"#), &[knee, "rpy", "not finite"]);
    assert_fails(&joint("revolute", r#"<axis xyz="0 0 0"/>"#), &[knee, "<axis", "must be a non-zero direction"]);
    assert_fails(&joint("prismatic", r#"<axis xyz="0 0 0"/>"#), &[knee, "<axis", "must be a non-zero direction"]);
    assert_fails(&joint("continuous", r#"<axis xyz="0 1"/>"#), &[knee, "axis", "expected 3 numbers"]);
    for kind in ["planar", "REVOLUTE"] {
        assert_fails(&joint(kind, ""), &[knee, &format!("unsupported type {kind:?}"), "floating, spherical"]);
    }
    assert_fails(&joint_robot(r#"<joint name="knee"><parent link="a"/><child link="b"/></joint>"#), &[knee, "no type"]);
    // The base cannot float twice.
    let error = parse_urdf(&joint("floating", ""), FLOATING).unwrap_err().to_string();
    assert!(error.contains(knee) && error.contains(r#"root link "a""#) && error.contains("float twice"), "{error}");
}

#[test]
fn floating_joints_are_three_slides_and_a_ball_and_spherical_joints_a_ball_with_a_warning() {
    let joint = |kind: &str| {
        joint_robot(&format!(
            r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/><origin xyz="1 2 3" rpy="0.1 0.2 0.3"/>
                   <limit lower="-1" upper="1" effort="0"/><dynamics damping="2"/></joint>"#
        ))
    };
    let floating = parse_urdf(&joint("floating"), FIXED).unwrap();
    assert!(floating.warnings.is_empty(), "{:?}", floating.warnings);
    let model = &floating.model;
    assert_eq!((model.nbodies(), model.nq(), model.nv()), (5, 7, 6));
    let names: Vec<&str> = (0..5).map(|b| model.name(b)).collect();
    assert_eq!(names, ["a", "b/knee:x", "b/knee:y", "b/knee:z", "b"]);
    for (body, axis) in [(1, Vector3::x()), (2, Vector3::y()), (3, Vector3::z())] {
        assert_eq!(*model.joint(body), Joint::Prismatic(axis));
        assert_eq!(model.parent(body), body - 1);
    }
    assert_eq!(*model.joint(4), Joint::Spherical);
    assert_placement(model, 1, &expected_placement([1.0, 2.0, 3.0], [0.1, 0.2, 0.3]));
    for body in 2..5 {
        assert_placement(model, body, &Transform::identity());
    }
    assert!(model.damping().iter().all(|d| *d == 2.0) && (1..5).all(|b| *model.limits(b) == JointLimits::NONE));
    // Below a floating base, a floating joint is another free body.
    assert_eq!(
        parse_urdf(&robot(r#"<link name="c"/><joint name="f" type="floating"><parent link="b"/><child link="c"/></joint>"#), FLOATING)
            .unwrap()
            .model
            .nv(),
        6 + 1 + 6
    );

    let spherical = parse_urdf(&joint("spherical"), FIXED).unwrap();
    assert_eq!((spherical.model.nbodies(), spherical.model.nq(), spherical.model.nv()), (2, 4, 3));
    assert_eq!(*spherical.model.joint(1), Joint::Spherical);
    assert_placement(&spherical.model, 1, &expected_placement([1.0, 2.0, 3.0], [0.1, 0.2, 0.3]));
    assert_eq!(spherical.warnings, [r#"joint "knee": type "spherical" is not in the URDF specification; read as a ball joint"#]);
    assert_fails(&joint("spherical"), &[r#"joint "knee": type "spherical""#, "(strict)"]);
}
