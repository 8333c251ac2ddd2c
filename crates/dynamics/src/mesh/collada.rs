//! COLLADA (.dae): the positions of the geometries a visual scene instantiates, through its nodes' transforms, in
//! metres with z up.

use std::collections::HashMap;

use nalgebra::{Matrix3, Matrix4, Rotation3, Unit, Vector3, Vector4};
use roxmltree::Node;

use super::{bad, grow};
use crate::Result;

/// COLLADA: the positions of every `<instance_geometry>` of the visual scene, through its nodes'
/// transforms (or every geometry as written when the scene instantiates none).
pub(super) fn collada(text: &str) -> Result<Vec<Vector3<f64>>> {
    let doc = crate::xml::parse(text, "mesh")?.map_err(bad)?;
    let root = doc.root_element();
    let asset = child(root, "asset");
    let meter = asset
        .and_then(|a| child(a, "unit"))
        .and_then(|u| u.attribute("meter"))
        .map_or(Ok(1.0), |m| m.trim().parse::<f64>().map_err(|_| bad(format!("<unit meter={m:?}> is not a number"))))?;
    // Turn the file's up axis onto z.
    let up = match asset.and_then(|a| child(a, "up_axis")).and_then(|u| u.text()).map(str::trim) {
        Some("Y_UP") => Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0),
        Some("X_UP") => Matrix3::new(0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0),
        _ => Matrix3::identity(),
    };
    let mut correction = Matrix4::identity();
    correction.fixed_view_mut::<3, 3>(0, 0).copy_from(&(up * meter));
    // The first element of each id, as a search in document order would find it.
    let mut ids: HashMap<&str, Node> = HashMap::new();
    for node in root.descendants() {
        if let Some(id) = node.attribute("id") {
            ids.entry(id).or_insert(node);
        }
    }
    let mut vertices = Vec::new();
    for scene in root.descendants().filter(|n| n.has_tag_name("visual_scene")) {
        instances(&ids, scene, correction, &mut vertices)?;
    }
    if vertices.is_empty() {
        for geometry in root.descendants().filter(|n| n.has_tag_name("geometry")) {
            positions(&ids, geometry, &correction, &mut vertices)?;
        }
    }
    Ok(vertices)
}

/// The geometries instantiated by the `<node>`s under `scene`, through the nodes' transforms, in document
/// order. The walk keeps its own stack: a file's nesting depth must not decide the depth of the call stack.
fn instances(ids: &HashMap<&str, Node>, scene: Node, correction: Matrix4<f64>, out: &mut Vec<Vector3<f64>>) -> Result<()> {
    let mut stack: Vec<(Node, Matrix4<f64>)> = scene.children().filter(|n| n.has_tag_name("node")).map(|n| (n, correction)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        if node.has_tag_name("instance_geometry") {
            let url = node.attribute("url").unwrap_or("").trim_start_matches('#');
            let geometry = ids.get(url).ok_or_else(|| bad(format!("<instance_geometry url=\"#{url}\"> names no geometry")))?;
            positions(ids, *geometry, &parent, out)?;
            continue;
        }
        let transform = parent * node_transform(node)?;
        let first = stack.len();
        stack
            .extend(node.children().filter(|item| item.has_tag_name("instance_geometry") || item.has_tag_name("node")).map(|item| (item, transform)));
        stack[first..].reverse();
    }
    Ok(())
}

/// The product of a `<node>`'s transform elements, in order.
fn node_transform(node: Node) -> Result<Matrix4<f64>> {
    let mut transform = Matrix4::identity();
    for step in node.children().filter(Node::is_element) {
        // At most one number more than any transform takes: enough to tell a wrong count, whatever the text's size.
        let numbers = || -> Result<Vec<f64>> {
            step.text()
                .unwrap_or("")
                .split_whitespace()
                .take(17)
                .map(|w| w.parse::<f64>().map_err(|_| bad(format!("<{}> holds {w:?}", step.tag_name().name()))))
                .collect()
        };
        let local = match step.tag_name().name() {
            "matrix" => {
                let m = numbers()?;
                (m.len() == 16).then(|| Matrix4::from_row_slice(&m)).ok_or_else(|| bad("<matrix> needs 16 numbers"))?
            }
            "translate" => match numbers()?[..] {
                [x, y, z] => Matrix4::new_translation(&Vector3::new(x, y, z)),
                _ => return Err(bad("<translate> needs 3 numbers")),
            },
            "rotate" => match numbers()?[..] {
                [x, y, z, degrees] => Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(x, y, z)), degrees.to_radians()).to_homogeneous(),
                _ => return Err(bad("<rotate> needs 4 numbers")),
            },
            "scale" => match numbers()?[..] {
                [x, y, z] => Matrix4::new_nonuniform_scaling(&Vector3::new(x, y, z)),
                _ => return Err(bad("<scale> needs 3 numbers")),
            },
            _ => continue,
        };
        transform *= local;
    }
    Ok(transform)
}

/// The POSITION inputs' floats of a `<geometry>`'s meshes, transformed, appended to `out`, which grows fallibly:
/// every instance of a geometry adds its positions again, so a small file can ask for far more than it holds.
fn positions(ids: &HashMap<&str, Node>, geometry: Node, transform: &Matrix4<f64>, out: &mut Vec<Vector3<f64>>) -> Result<()> {
    for mesh in geometry.children().filter(|n| n.has_tag_name("mesh")) {
        for vertices in mesh.children().filter(|n| n.has_tag_name("vertices")) {
            for input in vertices.children().filter(|n| n.has_tag_name("input") && n.attribute("semantic") == Some("POSITION")) {
                let id = input.attribute("source").unwrap_or("").trim_start_matches('#');
                let array =
                    ids.get(id).and_then(|s| child(*s, "float_array")).ok_or_else(|| bad(format!("POSITION source #{id} has no <float_array>")))?;
                let (mut numbers, mut p) = (0usize, [0.0; 3]);
                for word in array.text().unwrap_or("").split_whitespace() {
                    p[numbers % 3] = word.parse::<f64>().map_err(|_| bad(format!("<float_array> holds {word:?}")))?;
                    numbers += 1;
                    if numbers.is_multiple_of(3) {
                        grow(out, 1, "vertices")?;
                        out.push((transform * Vector4::new(p[0], p[1], p[2], 1.0)).xyz());
                    }
                }
                if !numbers.is_multiple_of(3) {
                    return Err(bad(format!("POSITION source #{id} has {numbers} numbers, not a multiple of 3")));
                }
            }
        }
    }
    Ok(())
}

fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(tag))
}
