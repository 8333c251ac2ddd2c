//! The ground: an infinite plane (z = 0, or placed anywhere), or a heightfield over the xy plane.

use nalgebra::DMatrix;
use parry3d_f64::math::{Matrix, Pose, Rotation, Vector};
use parry3d_f64::shape::{HeightFieldFlags, SharedShape};
use parry3d_f64::utils::Array2;

use crate::geometry::{to_pose, MAX_SHAPE_SIZE};
use crate::spatial::Transform;
use crate::validate::{finite, finite_vector, rotation};
use crate::{Error, Result};

/// The terrain under the robot, with its Coulomb friction coefficient.
#[derive(Debug, Clone, PartialEq)]
pub enum Ground {
    /// The plane z = 0 of the frame `placement` (plane to world), solid below: its normal is the
    /// placement's z axis.
    Plane {
        /// Coulomb friction coefficient, >= 0.
        friction: f64,
        /// The plane's frame in the world (the identity: the world's z = 0).
        placement: Transform,
    },
    /// Heights on a regular grid: `heights[(i, j)]` is the terrain height at
    /// x = (i − (nx − 1)/2) cell_size, y = (j − (ny − 1)/2) cell_size, so the grid is centred on the world
    /// origin; between samples each cell is split into two planar triangles. Outside the grid there is no
    /// ground.
    Heightfield {
        /// Terrain heights (m), nx x ny samples.
        heights: DMatrix<f64>,
        /// Spacing of the samples in x and y (m).
        cell_size: f64,
        /// Coulomb friction coefficient, >= 0.
        friction: f64,
    },
}

fn check_friction(friction: f64) -> Result<f64> {
    if finite("friction", friction)? < 0.0 {
        return Err(Error::invalid("friction", format!("must be >= 0, got {friction}")));
    }
    Ok(friction)
}

impl Ground {
    /// The plane z = 0 with friction coefficient `friction` (finite, >= 0).
    pub fn plane(friction: f64) -> Result<Self> {
        Self::placed_plane(friction, Transform::identity())
    }

    /// The plane z = 0 of the frame `placement` (a rotation and a finite translation, at most
    /// `MAX_SHAPE_SIZE` from the origin), as MuJoCo places a plane geom.
    pub fn placed_plane(friction: f64, placement: Transform) -> Result<Self> {
        rotation("placement", &placement.rotation)?;
        if !(finite_vector("placement", placement.translation)?.amax() <= MAX_SHAPE_SIZE) {
            return Err(Error::invalid("placement", format!("the plane's origin must be within {MAX_SHAPE_SIZE:e} m of the world's")));
        }
        Ok(Ground::Plane { friction: check_friction(friction)?, placement })
    }

    /// A heightfield of at least 2 x 2 finite samples spaced `cell_size` (> 0) apart.
    pub fn heightfield(heights: DMatrix<f64>, cell_size: f64, friction: f64) -> Result<Self> {
        if heights.nrows() < 2 || heights.ncols() < 2 {
            return Err(Error::invalid("heights", format!("needs at least 2 x 2 samples, got {} x {}", heights.nrows(), heights.ncols())));
        }
        if let Some(bad) = heights.iter().find(|h| !(h.abs() <= MAX_SHAPE_SIZE)) {
            return Err(Error::invalid("heights", format!("must be finite and at most {MAX_SHAPE_SIZE:e} m in magnitude, got {bad}")));
        }
        if finite("cell_size", cell_size)? <= 0.0 {
            return Err(Error::invalid("cell_size", format!("must be > 0, got {cell_size}")));
        }
        let extent = cell_size * (heights.nrows().max(heights.ncols()) - 1) as f64;
        if extent > MAX_SHAPE_SIZE {
            return Err(Error::invalid("cell_size", format!("the grid would span {extent:e} m, more than {MAX_SHAPE_SIZE:e} m")));
        }
        Ok(Ground::Heightfield { heights, cell_size, friction: check_friction(friction)? })
    }

    /// The ground's Coulomb friction coefficient.
    pub fn friction(&self) -> f64 {
        match self {
            Ground::Plane { friction, .. } | Ground::Heightfield { friction, .. } => *friction,
        }
    }

    /// The ground's parry shape and its pose in the world.
    pub(crate) fn shape(&self) -> (SharedShape, Pose) {
        match self {
            Ground::Plane { placement, .. } => (SharedShape::halfspace(Vector::Z), to_pose(placement)),
            Ground::Heightfield { heights, cell_size, .. } => {
                // Parry's heightfield lies in its local xz plane with heights along local y, rows along z
                // and columns along x, spanning [-1/2, 1/2] x scale. The rotation local (x, y, z) →
                // world (y, z, x) makes rows run along world x and columns along world y, so the sample
                // grid maps one to one; both are column-major.
                let (nx, ny) = heights.shape();
                let scale = Vector::new((ny - 1) as f64 * cell_size, 1.0, (nx - 1) as f64 * cell_size);
                let samples = Array2::new(nx, ny, heights.as_slice().to_vec());
                let rotation = Rotation::from_mat3(&Matrix::from_cols(Vector::Y, Vector::Z, Vector::X));
                // Internal edges fixed: a body sliding over the triangles' shared edges meets no ghost contact.
                (SharedShape::heightfield_with_flags(samples, scale, HeightFieldFlags::FIX_INTERNAL_EDGES), Pose::from_parts(Vector::ZERO, rotation))
            }
        }
    }
}
