//! Scan sources: a sequence of sweeps with first-firing stamps, read on demand.

use crate::dataset::ScanFile;
use crate::pointcloud::{read_pcd, PcdError, PointCloud};

/// Why a scan could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ScanLoadError {
    /// The scan file holds no point: the pipeline skips it (documented, reported).
    #[error(transparent)]
    EmptyFile(PcdError),
    /// An in-memory scan holds no point: skipped like an empty file.
    #[error("in-memory scan {index}: zero points")]
    EmptyInMemory {
        /// Index of the scan.
        index: usize,
    },
    /// The source has no scan at this index.
    #[error("no scan {index}")]
    NoScan {
        /// The index asked for.
        index: usize,
    },
    /// Malformed or unreadable file: the pipeline stops (exit code 2); the error names the
    /// file and, where it applies, the line.
    #[error(transparent)]
    Pcd(PcdError),
}

impl ScanLoadError {
    /// True for a scan without points (skipped, not an error of the run).
    pub fn is_empty_scan(&self) -> bool {
        matches!(
            self,
            ScanLoadError::EmptyFile(_) | ScanLoadError::EmptyInMemory { .. }
        )
    }
}

/// Sweeps in stamp order, loaded one at a time.
pub trait ScanSource: Sync {
    /// Number of scans.
    fn len(&self) -> usize;
    /// True when there is no scan.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// First-firing stamp of scan `index` (LiDAR clock), ns.
    fn stamp_ns(&self, index: usize) -> u64;
    /// Human-readable name for messages (the file path).
    fn name(&self, index: usize) -> String;
    /// Reads scan `index`.
    fn load(&self, index: usize) -> Result<PointCloud, ScanLoadError>;
}

/// The `lidar0/*.pcd` files of a dataset.
#[derive(Debug, Clone)]
pub struct FileScans {
    /// The files, sorted by stamp.
    pub files: Vec<ScanFile>,
}

impl ScanSource for FileScans {
    fn len(&self) -> usize {
        self.files.len()
    }

    fn stamp_ns(&self, index: usize) -> u64 {
        self.files.get(index).map_or(0, |f| f.stamp_ns)
    }

    fn name(&self, index: usize) -> String {
        self.files
            .get(index)
            .map_or_else(|| format!("scan {index}"), |f| f.path.display().to_string())
    }

    fn load(&self, index: usize) -> Result<PointCloud, ScanLoadError> {
        let file = self
            .files
            .get(index)
            .ok_or(ScanLoadError::NoScan { index })?;
        match read_pcd(&file.path) {
            Ok(cloud) => Ok(cloud),
            Err(e @ PcdError::ZeroPoints { .. }) => Err(ScanLoadError::EmptyFile(e)),
            Err(e) => Err(ScanLoadError::Pcd(e)),
        }
    }
}

/// Scans held in memory as `(stamp_ns, cloud)` (tests, small recordings).
impl ScanSource for Vec<(u64, PointCloud)> {
    fn len(&self) -> usize {
        Vec::len(self)
    }

    fn stamp_ns(&self, index: usize) -> u64 {
        self.get(index).map_or(0, |s| s.0)
    }

    fn name(&self, index: usize) -> String {
        format!("in-memory scan {index}")
    }

    fn load(&self, index: usize) -> Result<PointCloud, ScanLoadError> {
        match self.get(index) {
            Some((_, cloud)) if cloud.is_empty() => Err(ScanLoadError::EmptyInMemory { index }),
            Some((_, cloud)) => Ok(cloud.clone()),
            None => Err(ScanLoadError::NoScan { index }),
        }
    }
}
