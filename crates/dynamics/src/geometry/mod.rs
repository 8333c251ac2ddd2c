//! Geometric queries.

pub mod circle_line;
