//! `<compiler>`: the settings that decide how the rest of the file reads (angle unit, Euler sequence, mesh folder,
//! inertia from geoms and its bounds, limits, total mass).

use std::path::PathBuf;

use super::element::{numbers, El};
use super::invalid;
use crate::Result;

pub(super) struct Compiler {
    /// Radians per angle unit.
    pub(super) angle: f64,
    pub(super) eulerseq: [u8; 3],
    pub(super) meshdir: Option<PathBuf>,
    pub(super) inertia_from_geom: InertiaFromGeom,
    pub(super) group_range: [i64; 2],
    pub(super) boundmass: f64,
    pub(super) boundinertia: f64,
    pub(super) balanceinertia: bool,
    pub(super) autolimits: bool,
    /// `settotalmass` (> 0: every body's mass and inertia scaled so that they add up to it).
    pub(super) total_mass: f64,
}

#[derive(Clone, Copy, PartialEq)]
pub(super) enum InertiaFromGeom {
    Auto,
    Always,
    Never,
}

impl Compiler {
    /// The settings of every `<compiler>` element of `root`, merged in order over MuJoCo's defaults.
    pub(super) fn read(root: &El) -> Result<Compiler> {
        let mut compiler = Compiler {
            angle: std::f64::consts::PI / 180.0,
            eulerseq: *b"xyz",
            meshdir: None,
            inertia_from_geom: InertiaFromGeom::Auto,
            group_range: [0, 5],
            boundmass: 0.0,
            boundinertia: 0.0,
            balanceinertia: false,
            autolimits: true,
            total_mass: -1.0,
        };
        let mut assetdir = None;
        for c in root.elements("compiler") {
            let flag = |key: &str| -> Result<Option<bool>> {
                match c.attr(key) {
                    None => Ok(None),
                    Some("true") => Ok(Some(true)),
                    Some("false") => Ok(Some(false)),
                    Some(other) => Err(invalid(format!("<compiler {key}={other:?}>: expected true or false"))),
                }
            };
            match c.attr("angle") {
                None => {}
                Some("degree") => compiler.angle = std::f64::consts::PI / 180.0,
                Some("radian") => compiler.angle = 1.0,
                Some(other) => return Err(invalid(format!("<compiler angle={other:?}>: expected degree or radian"))),
            }
            if let Some(seq) = c.attr("eulerseq") {
                let bytes = seq.as_bytes();
                if bytes.len() != 3 || !bytes.iter().all(|b| b"xyzXYZ".contains(b)) {
                    return Err(invalid(format!("<compiler eulerseq={seq:?}>: expected three of x, y, z, X, Y, Z")));
                }
                compiler.eulerseq = [bytes[0], bytes[1], bytes[2]];
            }
            if let Some(dir) = c.attr("meshdir") {
                compiler.meshdir = Some(PathBuf::from(dir));
            }
            if let Some(dir) = c.attr("assetdir") {
                assetdir = Some(PathBuf::from(dir));
            }
            match c.attr("inertiafromgeom") {
                None => {}
                Some("auto") => compiler.inertia_from_geom = InertiaFromGeom::Auto,
                Some("true") => compiler.inertia_from_geom = InertiaFromGeom::Always,
                Some("false") => compiler.inertia_from_geom = InertiaFromGeom::Never,
                Some(other) => return Err(invalid(format!("<compiler inertiafromgeom={other:?}>: expected true, false or auto"))),
            }
            if let Some(text) = c.attr("inertiagrouprange") {
                match numbers(text, &|| "<compiler inertiagrouprange>".into())?.as_slice() {
                    [a, b] => compiler.group_range = [*a as i64, *b as i64],
                    _ => return Err(invalid("<compiler inertiagrouprange>: expected 2 numbers".into())),
                }
            }
            for (key, slot) in
                [("boundmass", &mut compiler.boundmass), ("boundinertia", &mut compiler.boundinertia), ("settotalmass", &mut compiler.total_mass)]
            {
                if let Some(text) = c.attr(key) {
                    match numbers(text, &|| format!("<compiler {key}>"))?.as_slice() {
                        [x] => *slot = *x,
                        _ => return Err(invalid(format!("<compiler {key}>: expected 1 number"))),
                    }
                }
            }
            if let Some(b) = flag("balanceinertia")? {
                compiler.balanceinertia = b;
            }
            if let Some(b) = flag("autolimits")? {
                compiler.autolimits = b;
            }
            if c.attr("coordinate").is_some_and(|v| v != "local") {
                return Err(invalid("<compiler coordinate=\"global\"> is not supported (MuJoCo removed it too)".into()));
            }
        }
        if compiler.meshdir.is_none() {
            compiler.meshdir = assetdir;
        }
        Ok(compiler)
    }
}
