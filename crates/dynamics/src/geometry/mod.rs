//! Geometric queries and collision shapes.

pub(crate) mod circle_line;
mod shape;

pub use circle_line::{circle_line, rotation_toward_line, Circle, CircleLine, CircleLineColumns, Line};
#[cfg(feature = "rapier")]
pub(crate) use shape::{from_pose, to_vector};
pub(crate) use shape::{from_vector, to_pose};
pub use shape::{Convex, Shape, ShapeKind, MAX_SHAPE_SIZE, MIN_DEFAULT_EDGE};
