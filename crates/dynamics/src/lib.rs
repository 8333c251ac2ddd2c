//! legkit-dynamics: the numeric kernels of legkit (mass-property algebra, geometry, rigid-body dynamics and their
//! derivatives, contact simulation, the balance agents).
//!
//! Conventions: SI units, right-handed frames with z up, and rigid transforms that map child to parent coordinates,
//! `x_parent = R x_child + t`. Comments cite papers by the keys of the repository's docs/references.md
//! ("[Featherstone 2008, Table 7.1]", "[Moll 2006, Algorithm 1]").
//!
//! The API: a [`Model`] (built body by body, or loaded by [`urdf`] and [`mjcf`]) and its [`Data`] workspace; the
//! dynamics [`algorithms`] and their derivatives, free functions on both; the contact simulation [`sim`]; the
//! mass-property algebra ([`MassProperties`]), spatial algebra ([`spatial`]) and [`geometry`] they rest on; the
//! distributed balance [`agents`]; and the argument checks the Python bindings share ([`validate`]). Every fallible
//! call returns [`Error`], naming the argument at fault.
//!
//! Cargo features: `rapier` (on by default, and in the Python wheel) builds `sim`'s Rapier reference backend;
//! without it the crate needs parry alone and `sim::Backend::Rapier` is refused with `Error::InvalidArgument`.

#![warn(missing_docs)]

pub mod agents;
pub mod algorithms;
mod error;
mod explog;
pub mod geometry;
mod joint;
mod mass;
pub mod mesh;
pub mod mjcf;
pub mod model;
pub mod sim;
pub mod spatial;
pub mod urdf;
pub mod validate;
mod xml;

pub use error::{Error, Result};
pub use geometry::{circle_line, rotation_toward_line, Circle, CircleLine, CircleLineColumns, Line};
pub use joint::Joint;
pub use mass::MassProperties;
pub use model::{Data, JointLimits, Model, ROOT_JOINT, STANDARD_GRAVITY};
pub use spatial::Transform;
