//! LiDAR point clouds: the in-memory [`PointCloud`], the PCD reader and writer
//! (docs/formats.md, section 2, `lidar0/<timestamp_ns>.pcd`)
//! and the voxel-grid filter.
//!
//! - Coordinates are `f64` ([`Point::xyz`]) like all host math; files carry
//!   them as `F4` (what every LiDAR driver and PCL expect) unless the writer
//!   is asked for `F8`.
//! - The reader accepts PCD v0.6/v0.7 `ascii`, `binary` and
//!   `binary_compressed` (LZF, column-major) data with any field layout. It
//!   reads the fields `x y z intensity t ring`, honouring each field's
//!   `SIZE`/`TYPE`/`COUNT` (first element used when `COUNT > 1`), ignores all
//!   other fields, defaults missing optional fields to zero and drops points
//!   with a non-finite coordinate. `x y z` are required.
//! - Every failure is a [`PcdError`] that names the file and, for the header,
//!   the 1-based line.

mod error;
mod header;
mod lzf;
pub mod ray_plane;
mod read;
mod voxel;
mod write;

#[cfg(test)]
mod tests;

use nalgebra::Vector3;

pub use error::PcdError;
pub use header::{PcdDataEncoding, PcdField, PcdHeader, PcdScalarType};
pub use read::{parse_pcd, read_pcd};
pub use voxel::{voxel_downsample, VoxelHasher, VoxelKey, VoxelMap};
pub use write::{encode_pcd, write_pcd, PcdEncoding, PcdWriteOptions};

/// One LiDAR return.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// Position in the sensor (or map) frame, metres, `f64` like all host math.
    pub xyz: Vector3<f64>,
    /// Return intensity / reflectivity, sensor units.
    pub intensity: f32,
    /// Firing time offset from the scan stamp (first firing of the sweep), ns.
    pub t_ns: u32,
    /// Beam index, 0 = lowest beam.
    pub ring: u16,
}

impl Point {
    /// A point at `xyz` with zero intensity, time offset and ring.
    pub fn from_xyz(xyz: Vector3<f64>) -> Self {
        Self {
            xyz,
            ..Self::default()
        }
    }
}

/// An unorganised point cloud (PCD `HEIGHT 1`; organised files are flattened
/// row by row and their missing returns dropped).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// The points, in file order.
    pub points: Vec<Point>,
}

impl PointCloud {
    /// A cloud of the given points.
    pub fn new(points: Vec<Point>) -> Self {
        Self { points }
    }

    /// A cloud of bare positions (zero intensity, time and ring).
    pub fn from_xyz(positions: impl IntoIterator<Item = Vector3<f64>>) -> Self {
        Self {
            points: positions.into_iter().map(Point::from_xyz).collect(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The positions only, in order.
    pub fn positions(&self) -> Vec<Vector3<f64>> {
        self.points.iter().map(|p| p.xyz).collect()
    }

    /// The cloud with every position mapped by `t_a_self` (`p_a = T_a_self p`).
    pub fn transformed(&self, t_a_self: &nalgebra::Isometry3<f64>) -> Self {
        let points = self
            .points
            .iter()
            .map(|p| Point {
                xyz: t_a_self.rotation * p.xyz + t_a_self.translation.vector,
                ..*p
            })
            .collect();
        Self { points }
    }
}
