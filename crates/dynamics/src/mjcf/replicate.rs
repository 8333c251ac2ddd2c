//! `<replicate>` expanded as MuJoCo's parser expands it: copies of its children in `<frame>`s, names suffixed.

use nalgebra::Vector3;

use super::element::{El, Name};
use super::reader::Reader;
use super::{invalid, BYTES_PER_ELEMENT, MAX_ELEMENTS};
use crate::mesh::cancel_point;
use crate::{Error, Result};

impl Reader<'_> {
    /// `el`'s `<replicate>` children (and theirs, and those nested in them) replaced, in place, by their copies, as
    /// MuJoCo's parser expands them (mjXReader::Body, google-deepmind/mujoco): copy i is a `<frame>` turned by i times
    /// `euler` (in the compiler's unit and sequence) and moved by the sum of `offset` turned by each earlier copy's
    /// rotation, holding the replicate's children with every `name` suffixed by `sep` and i, zero-padded to the digits
    /// of `count`; an inner replicate's suffix comes first. A `count` below 1 makes no copy, as in MuJoCo. `budget`
    /// is the elements still allowed (`MAX_ELEMENTS`); `seen` counts the elements walked, for cancellation.
    pub(super) fn expand_replicates(&self, el: &mut El, budget: &mut usize, seen: &mut usize) -> Result<()> {
        if !el.children.iter().any(|c| c.tag == "replicate" || !c.children.is_empty()) {
            return Ok(());
        }
        let children = std::mem::take(&mut el.children);
        for mut child in children {
            *seen += 1;
            cancel_point("from_mjcf", *seen)?;
            self.expand_replicates(&mut child, budget, seen)?;
            if child.tag != "replicate" {
                el.children.push(child);
                continue;
            }
            let what = child.what();
            let count = match child.attr("count").map(|c| c.trim().parse::<i64>()) {
                Some(Ok(count)) => usize::try_from(count).unwrap_or(0),
                Some(Err(_)) => return Err(invalid(format!("{what}: count={:?} is not an integer", child.attr("count").unwrap_or("")))),
                None => return Err(invalid(format!("{what}: count is required"))),
            };
            if let Some(inner) = child.children.iter().find(|c| matches!(c.tag.as_str(), "joint" | "freejoint")) {
                return Err(invalid(format!("{}: a <{}> cannot be a direct child of <replicate>, as in MuJoCo", inner.what(), inner.tag)));
            }
            // MuJoCo ignores an <inertial> there (in a <frame>, legkit would give it to the body).
            child.children.retain(|c| c.tag != "inertial");
            // The copies' elements, counted and their memory checked before any is made.
            let size = 1 + child.children.iter().map(El::size).sum::<usize>();
            let (added, bytes) = (count.saturating_mul(size), count.saturating_mul(size).saturating_mul(BYTES_PER_ELEMENT));
            let copies = format!("{what}: count={count} copies of {size} elements");
            if added > *budget {
                return Err(Error::too_large("mjcf", format!("{copies}: more than the {MAX_ELEMENTS} elements an MJCF may have")));
            }
            if !crate::validate::headroom(bytes) {
                return Err(Error::too_large("mjcf", format!("{copies} need up to {bytes} bytes, which cannot be allocated")));
            }
            *budget -= added;
            let offset = self.fixed::<3>(&child, "main", "offset")?.map_or_else(Vector3::zeros, Vector3::from);
            let euler = self.fixed::<3>(&child, "main", "euler")?.unwrap_or([0.0; 3]);
            let sep = child.attr("sep").unwrap_or("");
            let digits = count.to_string().len();
            let mut pos = Vector3::zeros();
            for i in 0..count {
                // Each copy's rotation from i times the angles, as MuJoCo computes it (not the product of i turns).
                let q = self.euler(euler.map(|a| a * i as f64));
                let mut attrs = vec![
                    (Name::from("pos"), format!("{} {} {}", pos.x, pos.y, pos.z)),
                    (Name::from("quat"), format!("{} {} {} {}", q.w, q.i, q.j, q.k)),
                ];
                attrs.extend(child.attrs.iter().filter(|(k, _)| k == "childclass").cloned());
                let suffix = format!("{sep}{i:0digits$}");
                let children = child.children.iter().map(|c| c.suffixed(&suffix, seen)).collect::<Result<_>>()?;
                el.children.push(El { tag: Name::from("frame"), attrs, children, at: child.at.clone() });
                pos += q * offset;
            }
        }
        Ok(())
    }
}

impl El {
    /// The elements of the tree below and including `self`.
    fn size(&self) -> usize {
        1 + self.children.iter().map(El::size).sum::<usize>()
    }

    /// A copy of the tree with `suffix` appended to every `name`; `seen` counts the elements copied, for cancellation.
    fn suffixed(&self, suffix: &str, seen: &mut usize) -> Result<El> {
        *seen += 1;
        cancel_point("from_mjcf", *seen)?;
        let attrs = self.attrs.iter().map(|(k, v)| (k.clone(), if k == "name" { format!("{v}{suffix}") } else { v.clone() })).collect();
        let children = self.children.iter().map(|c| c.suffixed(suffix, seen)).collect::<Result<_>>()?;
        Ok(El { tag: self.tag.clone(), attrs, children, at: self.at.clone() })
    }
}
