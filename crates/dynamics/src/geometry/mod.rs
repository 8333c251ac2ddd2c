//! Geometric queries and collision shapes.

pub mod circle_line;
mod shape;

#[cfg(feature = "rapier")]
pub(crate) use shape::{from_pose, to_vector};
pub(crate) use shape::{from_vector, to_pose};
pub use shape::{Convex, Shape, ShapeKind, MAX_SHAPE_SIZE, MIN_DEFAULT_EDGE};
