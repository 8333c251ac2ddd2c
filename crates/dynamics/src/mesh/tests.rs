//! Tests of the mesh readers, hull points, package paths and mesh inertia.

use std::borrow::Cow;
use std::path::PathBuf;

use nalgebra::Matrix3;

use super::collada::collada;
use super::obj::obj_faces;
use super::*;
use crate::Transform;

const CUBE: [[f64; 3]; 8] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.], [0., 0., 1.], [1., 0., 1.], [0., 1., 1.], [1., 1., 1.]];
/// The cube's 12 triangles as vertex indices.
const FACES: [[usize; 3]; 12] =
    [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]];

fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("legkit-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Every vertex read is a corner of `expected` (scaled, shifted), and every corner is read.
fn assert_corners(read: &[Vector3<f64>], expected: impl Fn(Vector3<f64>) -> Vector3<f64>) {
    let corners: Vec<Vector3<f64>> = CUBE.iter().map(|c| expected(Vector3::from(*c))).collect();
    for v in read {
        assert!(corners.iter().any(|c| (c - v).norm() < 1e-6), "{v:?} is no corner of {corners:?}");
    }
    for c in &corners {
        assert!(read.iter().any(|v| (c - v).norm() < 1e-6), "corner {c:?} missing");
    }
}

#[test]
fn binary_and_ascii_stl() {
    let mut binary = vec![0u8; 80];
    binary.extend((FACES.len() as u32).to_le_bytes());
    let mut ascii = String::from("solid cube\n");
    for face in FACES {
        binary.extend([0u8; 12]);
        ascii.push_str("facet normal 0 0 0\nouter loop\n");
        for &v in &face {
            binary.extend(CUBE[v].iter().flat_map(|x| (*x as f32).to_le_bytes()));
            ascii.push_str(&format!("vertex {} {} {}\n", CUBE[v][0], CUBE[v][1], CUBE[v][2]));
        }
        binary.extend([0u8; 2]);
        ascii.push_str("endloop\nendfacet\n");
    }
    ascii.push_str("endsolid cube\n");
    assert_corners(&mesh_vertices(&write("cube.STL", &binary)).unwrap(), |c| c);
    assert_corners(&mesh_vertices(&write("cube-ascii.stl", ascii.as_bytes())).unwrap(), |c| c);
    let truncated = &binary[..binary.len() - 7];
    assert!(mesh_vertices(&write("broken.stl", truncated)).is_err());
    // MuJoCo refuses the ASCII file, which the MJCF reader is told.
    assert_eq!(mesh_triangles(&write("cube.STL", &binary)).unwrap().1, MujocoDiffers::default());
    let refused = mesh_triangles(&write("cube-ascii.stl", ascii.as_bytes())).unwrap().1.refused.unwrap();
    assert!(refused.ends_with("cube-ascii.stl: an ASCII STL, which MuJoCo refuses (it reads binary STL only); legkit reads it"), "{refused}");
}

#[test]
fn a_vertex_list_beyond_memory_is_too_large_naming_the_mesh() {
    let error = grow(&mut Vec::<Vector3<f64>>::new(), usize::MAX / 32, "vertices").unwrap_err();
    assert!(matches!(error, Error::TooLarge { argument: "mesh", .. }) && error.to_string().contains("bytes"), "{error}");
}

#[test]
fn hull_points_are_all_the_points_up_to_the_bound_then_one_per_grid_cell_within_it() {
    let few: Vec<Vector3<f64>> = (0..HULL_POINTS).map(|k| Vector3::new(k as f64, (k * k) as f64, 1.0)).collect();
    let (same, note) = hull_points(&few).unwrap();
    assert!(matches!(same, Cow::Borrowed(_)) && note.is_none());
    // Each point three times, as an STL lists shared corners: the hull takes every distinct point, without a note.
    let repeated: Vec<Vector3<f64>> = few.iter().flat_map(|p| [*p; 3]).collect();
    let (distinct, note) = hull_points(&repeated).unwrap();
    assert!(note.is_none() && distinct[..] == few[..]);
    // 200,000 points on a helix around the unit sphere: a subset within a cell's diagonal of each of them.
    let many: Vec<Vector3<f64>> = (0..200_000)
        .map(|k| {
            let t = k as f64 / 200_000.0;
            let (z, phi) = (2.0 * t - 1.0, 2000.0 * t);
            let r = (1.0 - z * z).sqrt();
            Vector3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect();
    let (thinned, note) = hull_points(&many).unwrap();
    assert!(thinned.len() <= HULL_POINTS && thinned.len() > HULL_POINTS / 2, "{}", thinned.len());
    let bits = |p: &Vector3<f64>| p.map(f64::to_bits);
    let all: std::collections::HashSet<_> = many.iter().map(bits).collect();
    assert!(thinned.iter().all(|p| all.contains(&bits(p))));
    let within: f64 = note.unwrap().split("within ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!(many.iter().step_by(997).all(|p| thinned.iter().any(|q| (p - q).norm() <= within)));
}

#[test]
fn obj_vertices() {
    let text: String = CUBE.iter().map(|c| format!("v {} {} {}\n", c[0], c[1], c[2])).chain(["vn 0 0 1\nf 1 2 3\n".into()]).collect();
    assert_corners(&mesh_vertices(&write("cube.obj", text.as_bytes())).unwrap(), |c| c);
    assert!(mesh_vertices(&write("bad.obj", b"v 1 2\n")).unwrap_err().to_string().contains("line 1"));
}

#[test]
fn obj_groups_are_runs_of_faces_begun_by_g_or_o_lines_as_tinyobjloader_reads_them() {
    let cube: String = CUBE.iter().map(|c| format!("v {} {} {}\n", c[0], c[1], c[2])).collect();
    let groups = |body: &str| {
        let (_, obj) = obj_faces(&format!("{cube}{body}"), true).unwrap();
        (obj.groups, obj.first_group, obj.faces)
    };
    // Faces before any group line are the first group; `g` or `o` lines without faces after them begin none;
    // `usemtl` and a bare `g` (no space after the letter: tinyobjloader's test) begin none.
    assert_eq!(groups("f 1 2 3\nf 2 3 4\n"), (1, 2, 2));
    assert_eq!(groups("g a\no b\n  g c\nf 1 2 3\nusemtl m\nf 2 3 4\ng\nf 1 2 4\ng d\n"), (1, 3, 3));
    assert_eq!(groups("f 1 2 3\ng a\nf 2 3 4 5\n\to\tb\nf 1 2 4\nf 1 3 4\ng c\ng d\n"), (3, 1, 4));
    // What mesh_triangles says of it: the file, the groups and faces, and the first group's faces.
    let path = write("groups.obj", format!("{cube}f 1 2 3\ng a\nf 2 3 4 5\n").as_bytes());
    let ((_, triangles), differs) = mesh_triangles(&path).unwrap();
    assert_eq!(triangles.len(), 3, "every group's faces are taken");
    let expected = format!(
        "{}: its 2 faces lie in 2 groups (OBJ `g`/`o` lines): MuJoCo's mass takes only the first group's 1 faces, legkit's is \
             the whole mesh's",
        path.display()
    );
    assert_eq!(differs, MujocoDiffers { mass: vec![expected], refused: None });
    let one = write("one.obj", format!("{cube}g a\nf 1 2 3\n").as_bytes());
    assert_eq!(mesh_triangles(&one).unwrap().1, MujocoDiffers::default());
}

#[test]
fn collada_units_up_axis_and_node_transforms() {
    let floats: Vec<String> = CUBE.iter().flatten().map(|x| x.to_string()).collect();
    let dae = format!(
        r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="0.001"/><up_axis>Y_UP</up_axis></asset>
  <library_geometries><geometry id="cube"><mesh>
    <source id="cube-positions"><float_array id="cube-array" count="24">{}</float_array></source>
    <vertices id="cube-vertices"><input semantic="POSITION" source="#cube-positions"/></vertices>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="scene">
    <node id="outer"><translate>10 0 0</translate>
      <node id="inner"><scale>2 2 2</scale><instance_geometry url="#cube"/></node>
    </node>
  </visual_scene></library_visual_scenes>
</COLLADA>"##,
        floats.join(" ")
    );
    // Millimetres, y up: (x, y, z) mm -> (x, -z, y) m, after the nodes' scale 2 then shift 10 along x.
    let read = mesh_vertices(&write("cube.dae", dae.as_bytes())).unwrap();
    assert_corners(&read, |c| Vector3::new(2.0 * c.x + 10.0, -2.0 * c.z, 2.0 * c.y) * 1e-3);
}

#[test]
fn package_paths_resolve_against_the_search_path_then_the_urdf_folders_ancestors() {
    let root = std::env::temp_dir().join(format!("legkit-mesh-{}", std::process::id()));
    std::fs::create_dir_all(root.join("pkg_a/meshes")).unwrap();
    std::fs::write(root.join("pkg_a/meshes/part.stl"), b"solid\nendsolid\n").unwrap();
    let found = resolve_mesh("package://pkg_a/meshes/part.stl", None, std::slice::from_ref(&root)).unwrap();
    assert_eq!(found, root.join("pkg_a/meshes/part.stl"));
    // The package folder itself as a search folder.
    assert_eq!(resolve_mesh("package://pkg_a/meshes/part.stl", None, &[root.join("pkg_a")]).unwrap(), found);
    let urdf_dir = root.join("pkg_a/urdf");
    std::fs::create_dir_all(&urdf_dir).unwrap();
    assert_eq!(resolve_mesh("package://pkg_a/meshes/part.stl", Some(&urdf_dir), &[]).unwrap(), found);
    assert_eq!(resolve_mesh("../meshes/part.stl", Some(&urdf_dir), &[]).unwrap(), urdf_dir.join("../meshes/part.stl"));
    let missing = resolve_mesh("package://nowhere/x.stl", Some(&urdf_dir), &[]).unwrap_err().to_string();
    assert!(missing.contains("package_dirs") && missing.contains("nowhere"), "{missing}");
    // A package name cannot climb out of its package, even to a file that exists.
    for escape in ["package://pkg_a/../pkg_a/meshes/part.stl", "package://../pkg_a/meshes/part.stl", "model://pkg_a/../../x.stl"] {
        let refused = resolve_mesh(escape, Some(&urdf_dir), std::slice::from_ref(&root)).unwrap_err();
        assert!(refused.argument() == "filename" && refused.to_string().contains("outside its package"), "{refused}");
    }
    // Empty segments are skipped, as Pinocchio and ROS read them: example-robot-data's three slashes, and a
    // root inside the name stays below the package.
    assert_eq!(resolve_mesh("package:///pkg_a/meshes/part.stl", None, std::slice::from_ref(&root)).unwrap(), found);
    assert_eq!(resolve_mesh("model://pkg_a//meshes/part.stl", None, std::slice::from_ref(&root)).unwrap(), found);
    assert_eq!(resolve_mesh("package://pkg_a//etc/passwd", None, std::slice::from_ref(&root)).unwrap_err().argument(), "package_dirs");
    // A relative name not beside the URDF: in the package folders, as Pinocchio looks for it.
    assert_eq!(resolve_mesh("meshes/part.stl", None, &[root.join("pkg_a")]).unwrap(), root.join("pkg_a").join("meshes/part.stl"));
    // Symbolic links are followed: inside the package, and out of it to a file of the name's kind (colcon's
    // --symlink-install links each installed file to its source); out of it to another kind, refused.
    std::fs::write(root.join("source.stl"), b"solid\nendsolid\n").unwrap();
    std::fs::write(root.join("secret.key"), b"not a mesh").unwrap();
    let link = |target: &str, name: &str| {
        let path = root.join("pkg_a/meshes").join(name);
        let _ = std::fs::remove_file(&path);
        std::os::unix::fs::symlink(root.join(target), &path).unwrap();
        path
    };
    let (inward, installed, disguised) =
        (link("pkg_a/meshes/part.stl", "inward.stl"), link("source.stl", "installed.stl"), link("secret.key", "key.stl"));
    assert_eq!(resolve_mesh("package://pkg_a/meshes/inward.stl", None, std::slice::from_ref(&root)).unwrap(), inward);
    assert_eq!(resolve_mesh("package://pkg_a/meshes/installed.stl", None, std::slice::from_ref(&root)).unwrap(), installed);
    let refused = resolve_mesh("package://pkg_a/meshes/key.stl", None, std::slice::from_ref(&root)).unwrap_err();
    assert!(refused.argument() == "filename" && refused.to_string().contains("another kind"), "{refused} ({disguised:?})");
    // A FIFO is refused before it is opened (opening one blocks until a writer comes).
    let fifo = root.join("pipe.stl");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    if made {
        let refused = mesh_vertices(&fifo).unwrap_err().to_string();
        assert!(refused.contains("not a regular file"), "{refused}");
    }
}

#[test]
fn collada_nesting_deeper_than_the_call_stack_allows() {
    let depth = 100_000;
    let cube: String = (0..8).map(|k| format!("{} {} {} ", k & 1, (k >> 1) & 1, (k >> 2) & 1)).collect();
    let text = format!(
        "<COLLADA><library_geometries><geometry id=\"g\"><mesh><source id=\"p\"><float_array>{cube}</float_array></source>\
             <vertices id=\"v\"><input semantic=\"POSITION\" source=\"#p\"/></vertices></mesh></geometry></library_geometries>\
             <library_visual_scenes><visual_scene>{}<instance_geometry url=\"#g\"/>{}</visual_scene></library_visual_scenes></COLLADA>",
        "<node><translate>1 0 0</translate>".repeat(depth),
        "</node>".repeat(depth)
    );
    let vertices = collada(&text).unwrap();
    assert_eq!(vertices.len(), 8);
    assert_eq!(vertices[0], Vector3::new(depth as f64, 0.0, 0.0));
}

/// A box's triangles, half-sizes `h`, turned by `r` and moved by `t`, with every other face turned inside out.
fn box_mesh(h: Vector3<f64>, r: &Matrix3<f64>, t: &Vector3<f64>) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
    let corner = |i: usize| {
        r * Vector3::new(
            h.x * if i & 1 == 0 { -1.0 } else { 1.0 },
            h.y * if i & 2 == 0 { -1.0 } else { 1.0 },
            h.z * if i & 4 == 0 { -1.0 } else { 1.0 },
        ) + t
    };
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let faces = quads
        .iter()
        .enumerate()
        .flat_map(|(k, q)| if k % 2 == 0 { [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] } else { [[q[0], q[2], q[1]], [q[0], q[3], q[2]]] })
        .collect();
    ((0..8).map(corner).collect(), faces)
}

#[test]
fn a_box_meshs_legacy_mass_is_the_solid_box_whatever_its_faces_orientation() {
    let (h, r, t) =
        (Vector3::new(0.1, 0.2, 0.3), Transform::rotation_about(&Vector3::new(1.0, 2.0, 3.0).normalize(), 0.7), Vector3::new(0.5, -1.0, 2.0));
    let (vertices, faces) = box_mesh(h, &r, &t);
    let mass = mesh_mass(&vertices, &faces, "legacy").unwrap();
    let inertia = r
        * Matrix3::from_diagonal(&Vector3::new(h.y * h.y + h.z * h.z, h.x * h.x + h.z * h.z, h.x * h.x + h.y * h.y))
        * r.transpose()
        * (8.0 * h.x * h.y * h.z / 3.0);
    assert!((mass.volume - 8.0 * h.x * h.y * h.z).abs() < 1e-15);
    assert!((mass.com - t).norm() < 1e-14);
    assert!((mass.inertia - inertia).norm() < 1e-9 * inertia.norm(), "{} vs {inertia}", mass.inertia);
    // "exact" sums signed pyramids: the inside-out faces cancel their opposites. MuJoCo refuses the mesh before:
    // the inside-out faces run along the edges they share with their neighbours in the same direction.
    assert!(mesh_mass(&vertices, &faces, "exact").is_err());
    assert_eq!(inconsistent_edge(&vertices, &faces).unwrap(), Some([1, 5]));
    let outward: Vec<[usize; 3]> = faces.iter().enumerate().map(|(k, f)| if (k / 2) % 2 == 1 { [f[0], f[2], f[1]] } else { *f }).collect();
    assert_eq!(inconsistent_edge(&vertices, &outward).unwrap(), None);
    // Faces of no area do not count.
    let sliver = [outward.as_slice(), &[[0, 0, 1], [0, 0, 1]]].concat();
    assert_eq!(inconsistent_edge(&vertices, &sliver).unwrap(), None);
}
