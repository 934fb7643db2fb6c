//! The NDT target: per-resolution voxel maps of Gaussians, built from
//! per-cell sums that can also be added to and subtracted from (local map).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::{NdtError, NdtParams};
use crate::pointcloud::{VoxelKey, VoxelMap};

/// One Gaussian cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NdtCell {
    /// Mean of the cell's points, m.
    pub mean: Vector3<f64>,
    /// Inverse of the regularised covariance, 1/m^2.
    pub inv_cov: Matrix3<f64>,
    /// Number of points.
    pub count: usize,
}

/// Sufficient statistics of one voxel, relative to the voxel's corner so the
/// sums stay well conditioned far from the origin.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct CellStats {
    pub(crate) count: usize,
    pub(crate) sum: Vector3<f64>,
    pub(crate) sum_sq: Matrix3<f64>,
}

/// Per-voxel sums at one resolution.
#[derive(Debug, Clone, Default)]
pub(crate) struct StatsGrid {
    pub(crate) resolution: f64,
    pub(crate) cells: VoxelMap<CellStats>,
}

impl StatsGrid {
    pub(crate) fn new(resolution: f64) -> Self {
        Self {
            resolution,
            cells: VoxelMap::default(),
        }
    }

    fn corner(&self, key: VoxelKey) -> Vector3<f64> {
        Vector3::new(
            f64::from(key.0[0]),
            f64::from(key.0[1]),
            f64::from(key.0[2]),
        ) * self.resolution
    }

    /// Adds (`sign = 1.0`) or removes (`sign = -1.0`) points.
    pub(crate) fn accumulate(&mut self, points: &[Vector3<f64>], sign: f64) {
        let inv = self.resolution.recip();
        for p in points {
            let key = VoxelKey::of(p, inv);
            let local = p - self.corner(key);
            let cell = self.cells.entry(key).or_default();
            if sign > 0.0 {
                cell.count += 1;
            } else {
                cell.count = cell.count.saturating_sub(1);
            }
            cell.sum += sign * local;
            cell.sum_sq += sign * local * local.transpose();
        }
        if sign < 0.0 {
            self.cells.retain(|_, c| c.count > 0);
        }
    }

    /// The Gaussians of the cells with enough points.
    pub(crate) fn to_map(&self, params: &NdtParams) -> NdtMap {
        let mut index = VoxelMap::default();
        let mut cells = Vec::new();
        for (key, stats) in &self.cells {
            if stats.count < params.min_points_per_cell {
                continue;
            }
            if let Some(cell) = gaussian(stats, self.corner(*key), params.eigenvalue_ratio) {
                index.insert(*key, cells.len() as u32);
                cells.push(cell);
            }
        }
        NdtMap {
            resolution: self.resolution,
            index,
            cells,
        }
    }
}

/// Mean and regularised inverse covariance from sums (Magnusson sec. 6.2:
/// eigenvalues below `ratio * lambda_max` are raised to it).
fn gaussian(stats: &CellStats, corner: Vector3<f64>, ratio: f64) -> Option<NdtCell> {
    let n = stats.count as f64;
    let mean_local = stats.sum / n;
    let cov = (stats.sum_sq - n * mean_local * mean_local.transpose()) / (n - 1.0);
    let eig = SymmetricEigen::new(cov);
    let lambda_max = eig.eigenvalues.max();
    if !(lambda_max.is_finite() && lambda_max > 1e-12) {
        return None;
    }
    let floor = ratio * lambda_max;
    let inv_diag = eig.eigenvalues.map(|l| 1.0 / l.max(floor));
    let inv_cov =
        eig.eigenvectors * Matrix3::from_diagonal(&inv_diag) * eig.eigenvectors.transpose();
    Some(NdtCell {
        mean: corner + mean_local,
        inv_cov,
        count: stats.count,
    })
}

/// Gaussians of one resolution, looked up by voxel.
#[derive(Debug, Clone, Default)]
pub struct NdtMap {
    resolution: f64,
    index: VoxelMap<u32>,
    cells: Vec<NdtCell>,
}

impl NdtMap {
    /// Cell size, m.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The Gaussian cells (in no particular order).
    pub fn cells(&self) -> &[NdtCell] {
        &self.cells
    }

    /// The cell of voxel `key`, if it has a Gaussian.
    #[inline]
    pub fn get(&self, key: VoxelKey) -> Option<&NdtCell> {
        self.index.get(&key).map(|&i| &self.cells[i as usize])
    }
}

/// The target of a registration: one [`NdtMap`] per resolution of
/// [`NdtParams::resolutions`], in the same order.
#[derive(Debug, Clone, Default)]
pub struct NdtTarget {
    levels: Vec<NdtMap>,
}

impl NdtTarget {
    /// Builds the maps from target points (already voxel-filtered as wanted).
    pub fn build(points: &[Vector3<f64>], params: &NdtParams) -> Result<Self, NdtError> {
        params.validate()?;
        let grids: Vec<StatsGrid> = params
            .resolutions
            .iter()
            .map(|&r| {
                let mut grid = StatsGrid::new(r);
                grid.accumulate(points, 1.0);
                grid
            })
            .collect();
        Self::from_grids(&grids, params)
    }

    pub(crate) fn from_grids(grids: &[StatsGrid], params: &NdtParams) -> Result<Self, NdtError> {
        let levels = grids
            .iter()
            .map(|g| {
                let map = g.to_map(params);
                if map.cells.is_empty() {
                    Err(NdtError::EmptyTarget {
                        resolution: g.resolution,
                        min_points: params.min_points_per_cell,
                    })
                } else {
                    Ok(map)
                }
            })
            .collect::<Result<_, _>>()?;
        Ok(Self { levels })
    }

    /// The maps, coarse to fine.
    pub fn levels(&self) -> &[NdtMap] {
        &self.levels
    }
}
