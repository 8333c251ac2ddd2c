//! Geometric queries and collision shapes.

pub mod circle_line;
mod shape;

pub(crate) use shape::{from_pose, from_vector, to_pose, to_vector};
pub use shape::{Convex, Shape, ShapeKind, MAX_SHAPE_SIZE, MIN_DEFAULT_EDGE};
