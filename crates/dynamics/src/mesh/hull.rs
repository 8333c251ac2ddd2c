//! The points a collision mesh's convex hull is taken over: all of its distinct vertices up to `HULL_POINTS`, then
//! one per cell of a grid over them.

use std::borrow::Cow;
use std::collections::HashMap;

use nalgebra::Vector3;

use super::cancel_point;
use crate::{Error, Result};

/// At most this many points go into a collision mesh's convex hull. Parry takes it in one call that cannot be
/// interrupted, in time growing faster than the number of points on the hull: about 0.7 s of CPU for this
/// many points on a sphere, 7.7 s for 100,000 and 52 s for 300,000 (release build).
pub const HULL_POINTS: usize = 25_000;

/// `points` without repeats (equal to the bit), in the order they first appear, and the index among them of each
/// point. Interruptible.
pub(super) fn distinct_points(points: &[Vector3<f64>]) -> Result<(Vec<Vector3<f64>>, Vec<usize>)> {
    let too_large = || Error::too_large("mesh", format!("cannot allocate the set of its {} vertices", points.len()));
    let mut seen: HashMap<[u64; 3], usize> = HashMap::new();
    let (mut distinct, mut index) = (Vec::new(), crate::validate::with_capacity("mesh", points.len())?);
    for (k, p) in points.iter().enumerate() {
        cancel_point("mesh", k)?;
        if seen.len() == seen.capacity() {
            seen.try_reserve(seen.len().max(16)).map_err(|_| too_large())?;
            distinct.try_reserve(seen.capacity().saturating_sub(distinct.len())).map_err(|_| too_large())?;
        }
        index.push(*seen.entry(p.map(f64::to_bits).into()).or_insert_with(|| {
            distinct.push(*p);
            distinct.len() - 1
        }));
    }
    Ok((distinct, index))
}

/// The points a hull is taken over (`hull_points`), and the note saying they are fewer than the mesh's.
pub(crate) type HullPoints<'a> = (Cow<'a, [Vector3<f64>]>, Option<String>);

/// The points a convex hull of `points` is taken over, and a note when they are fewer than the mesh's
/// distinct points: beyond `HULL_POINTS` distinct points, one per cell of the finest grid over the bounding
/// box that leaves at most that many (the one farthest from the box's centre), so that every point lies within
/// a cell's diagonal of the hull taken, which lies inside the mesh's. Interruptible (`validate::cancellable`).
pub(crate) fn hull_points(points: &[Vector3<f64>]) -> Result<HullPoints<'_>> {
    if points.len() <= HULL_POINTS {
        return Ok((Cow::Borrowed(points), None));
    }
    // An STL lists each triangle's corners: a closed mesh has about a sixth as many distinct points.
    let (distinct, _) = distinct_points(points)?;
    if distinct.len() <= HULL_POINTS {
        return Ok((Cow::Owned(distinct), None));
    }
    let points = &distinct[..];
    let (lower, upper) =
        points.iter().fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let centre = (lower + upper) / 2.0;
    let mut cells = 1024usize;
    loop {
        let size = (upper - lower).map(|e| e / cells as f64);
        let mut kept: HashMap<[usize; 3], usize> = HashMap::new();
        for (k, p) in points.iter().enumerate() {
            cancel_point("mesh", k)?;
            let cell = [0, 1, 2].map(|i| if size[i] > 0.0 { (((p[i] - lower[i]) / size[i]) as usize).min(cells - 1) } else { 0 });
            if kept.len() == kept.capacity() {
                kept.try_reserve(kept.len().max(16))
                    .map_err(|_| Error::too_large("mesh", format!("cannot allocate the grid over its {} vertices", points.len())))?;
            }
            let at = kept.entry(cell).or_insert(k);
            if (p - centre).norm_squared() > (points[*at] - centre).norm_squared() {
                *at = k;
            }
            if kept.len() > HULL_POINTS && cells > 1 {
                break;
            }
        }
        if kept.len() <= HULL_POINTS || cells == 1 {
            let mut chosen: Vec<usize> = kept.into_values().collect();
            chosen.sort_unstable();
            let note = (chosen.len() < points.len()).then(|| {
                format!(
                    "its convex hull is taken over {} of its {} distinct vertices (each within {:.2e} m of one)",
                    chosen.len(),
                    points.len(),
                    size.norm()
                )
            });
            let mut out = crate::validate::with_capacity("mesh", chosen.len())?;
            out.extend(chosen.into_iter().map(|k| points[k]));
            return Ok((Cow::Owned(out), note));
        }
        cells = cells * 3 / 4;
    }
}
