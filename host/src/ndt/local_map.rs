//! Scan-to-local-map registration: a sliding window of the last K scans,
//! each deskewed by the caller, moved into the map frame and
//! voxel-downsampled on insertion. Cell sums are added on insertion and
//! subtracted on eviction; the Gaussians are refreshed lazily on the next
//! alignment (cost O(cells), independent of K).

use std::collections::VecDeque;

use nalgebra::{Isometry3, Vector3};

use super::map::{NdtTarget, StatsGrid};
use super::{align, NdtError, NdtParams, NdtResult};
use crate::pointcloud::{voxel_downsample, PointCloud};

/// A sliding-window NDT map in a fixed "map" frame.
#[derive(Debug, Clone)]
pub struct LocalMap {
    capacity: usize,
    voxel_m: f64,
    params: NdtParams,
    scans: VecDeque<Vec<Vector3<f64>>>,
    grids: Vec<StatsGrid>,
    target: Option<NdtTarget>,
}

impl LocalMap {
    /// An empty map keeping the last `capacity` (at least 1) scans, each
    /// downsampled with voxels of `voxel_m` (0 = no filter).
    pub fn new(capacity: usize, voxel_m: f64, params: NdtParams) -> Result<Self, NdtError> {
        params.validate()?;
        let grids = params
            .resolutions
            .iter()
            .map(|&r| StatsGrid::new(r))
            .collect();
        Ok(Self {
            capacity: capacity.max(1),
            voxel_m,
            params,
            scans: VecDeque::new(),
            grids,
            target: None,
        })
    }

    /// Adds a (deskewed) scan whose pose in the map frame is `t_map_scan`,
    /// evicting the oldest when full.
    pub fn insert(&mut self, scan: &PointCloud, t_map_scan: &Isometry3<f64>) {
        let in_map = voxel_downsample(&scan.transformed(t_map_scan), self.voxel_m).positions();
        if self.scans.len() == self.capacity {
            if let Some(old) = self.scans.pop_front() {
                self.grids.iter_mut().for_each(|g| g.accumulate(&old, -1.0));
            }
        }
        self.grids
            .iter_mut()
            .for_each(|g| g.accumulate(&in_map, 1.0));
        self.scans.push_back(in_map);
        self.target = None;
    }

    /// Scans currently held.
    pub fn len(&self) -> usize {
        self.scans.len()
    }

    /// True when no scan has been inserted.
    pub fn is_empty(&self) -> bool {
        self.scans.is_empty()
    }

    /// Removes every scan.
    pub fn clear(&mut self) {
        self.scans.clear();
        self.grids.iter_mut().for_each(|g| g.cells.clear());
        self.target = None;
    }

    /// The current NDT target (rebuilt if scans changed since the last call).
    pub fn target(&mut self) -> Result<&NdtTarget, NdtError> {
        let target = match self.target.take() {
            Some(t) => t,
            None => NdtTarget::from_grids(&self.grids, &self.params)?,
        };
        Ok(self.target.insert(target))
    }

    /// Registers `scan` (used as given: voxel-filter it first) to the map
    /// from `guess` = initial `T_map_scan`.
    pub fn align(
        &mut self,
        scan: &PointCloud,
        guess: &Isometry3<f64>,
    ) -> Result<NdtResult, NdtError> {
        let params = self.params.clone();
        let target = self.target()?;
        align(target, &scan.positions(), guess, &params)
    }
}
