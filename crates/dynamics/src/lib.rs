//! legkit-dynamics: the numeric kernels of legkit (mass-property algebra, geometry, rigid-body dynamics and their
//! derivatives, contact simulation, the balance agents).
//!
//! Conventions: SI units, right-handed frames with z up, and rigid transforms that map child to parent coordinates,
//! `x_parent = R x_child + t`. Comments cite papers by the keys of the repository's docs/references.md
//! ("[Featherstone 2008, Table 7.1]", "[Moll 2006, Algorithm 1]").
//!
//! The API: a [`Model`] (built body by body, or loaded by [`urdf`] and [`mjcf`]) and its [`Data`] workspace; the
//! dynamics [`algorithms`] and their derivatives, free functions on both, which check their arguments (sizes,
//! finiteness, unit quaternions, a `Data` built for that model) and their results; batches of them on all cores with
//! per-thread workspaces and cancellation ([`parallel`]); the contact simulation [`sim`]; the mass-property algebra
//! ([`MassProperties`]), spatial algebra ([`spatial`]) and [`geometry`] they rest on; the distributed balance
//! [`agents`]; and the argument checks shared with the Python bindings ([`validate`]). Every fallible call returns
//! [`Error`], naming the argument at fault; `examples/` has a URDF robot's dynamics and a simulation.
//!
//! ```
//! use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
//! use nalgebra::{Matrix3, Vector3};
//!
//! let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
//! let mut model = Model::new(false, MassProperties::zero(), "base");
//! model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "link", JointLimits::NONE)?;
//! let mut data = Data::new(&model);
//! let ddq = algorithms::aba(&model, &mut data, &[0.3], &[0.0], &[0.0], None)?;
//! assert!(ddq[0] < 0.0, "the link swings down");
//! let error = algorithms::aba(&model, &mut data, &[0.3, 0.1], &[0.0], &[0.0], None).unwrap_err();
//! assert_eq!(error.to_string(), "q: expected length 1, got 2");
//! # Ok::<(), legkit_dynamics::Error>(())
//! ```
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
pub mod parallel;
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
