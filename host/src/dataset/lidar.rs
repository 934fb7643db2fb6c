//! `lidar0/`: one PCD file per sweep named by its first-firing stamp, and `lidar.yaml`
//! (informative sensor description). Scans are listed here and read one at a time by the
//! consumer (a 60 s 128 x 1024 recording is gigabytes of points).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::csv::io_error;
use super::error::DatasetError;
use super::yaml::{check_positive, read_yaml, write_text, yaml_float};

/// The LiDAR directory, relative to the dataset root.
pub const LIDAR_DIR: &str = "lidar0";
/// The LiDAR description.
pub const LIDAR_YAML: &str = "lidar0/lidar.yaml";

/// One scan file: `lidar0/<stamp_ns>.pcd`.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct ScanFile {
    /// First-firing stamp (LiDAR clock), from the file name, ns.
    pub stamp_ns: u64,
    /// The file.
    pub path: PathBuf,
}

/// Lists `dir`'s `*.pcd` files sorted by stamp. A `.pcd` whose name is not a decimal ns
/// stamp, or two files with the same stamp (`0123.pcd` and `123.pcd`), are errors naming
/// the file; other files are ignored.
pub fn list_scans(dir: &Path) -> Result<Vec<ScanFile>, DatasetError> {
    if !dir.is_dir() {
        return Err(DatasetError::MissingFile {
            path: dir.to_path_buf(),
        });
    }
    let entries = std::fs::read_dir(dir).map_err(|e| io_error(dir, e))?;
    let mut scans = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| io_error(dir, e))?.path();
        if path.extension().and_then(|e| e.to_str()) != Some("pcd") {
            continue;
        }
        let stamp = path
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.parse::<u64>().ok());
        let Some(stamp_ns) = stamp else {
            return Err(DatasetError::InvalidValue {
                path,
                message: "a scan's file name must be its first-firing stamp in ns \
                          (lidar0/<timestamp_ns>.pcd)"
                    .into(),
            });
        };
        scans.push(ScanFile { stamp_ns, path });
    }
    scans.sort();
    if let Some(w) = scans.windows(2).find(|w| w[0].stamp_ns == w[1].stamp_ns) {
        return Err(DatasetError::InvalidValue {
            path: w[1].path.clone(),
            message: format!("same stamp {} ns as {}", w[0].stamp_ns, w[0].path.display()),
        });
    }
    Ok(scans)
}

/// `lidar0/lidar.yaml` (informative; every key optional, unknown keys ignored).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LidarYaml {
    /// Beams.
    #[serde(default)]
    pub rings: Option<u32>,
    /// Firings per sweep.
    #[serde(default)]
    pub columns: Option<u32>,
    /// Sweeps per second.
    #[serde(default)]
    pub scan_rate_hz: Option<f64>,
    /// 1-sigma range noise, m.
    #[serde(default)]
    pub range_noise_m: Option<f64>,
}

impl LidarYaml {
    /// Reads and validates (rates and noise positive when given).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let y: Self = read_yaml(path)?;
        if let Some(rate) = y.scan_rate_hz {
            check_positive(path, "scan_rate_hz", rate)?;
        }
        if let Some(noise) = y.range_noise_m {
            check_positive(path, "range_noise_m", noise)?;
        }
        Ok(y)
    }

    /// Writes the YAML file.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        write_text(path.as_ref(), &self.to_yaml_string())
    }

    /// The YAML text [`LidarYaml::write`] writes.
    pub fn to_yaml_string(&self) -> String {
        let mut text = String::from("# spinning LiDAR (informative)\n");
        if let Some(v) = self.rings {
            text.push_str(&format!("rings: {v}\n"));
        }
        if let Some(v) = self.columns {
            text.push_str(&format!("columns: {v}\n"));
        }
        if let Some(v) = self.scan_rate_hz {
            text.push_str(&format!("scan_rate_hz: {}\n", yaml_float(v)));
        }
        if let Some(v) = self.range_noise_m {
            text.push_str(&format!("range_noise_m: {}\n", yaml_float(v)));
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    #[test]
    fn scans_are_listed_by_stamp_and_bad_names_are_named() -> TestResult {
        let dir = tempfile::tempdir()?;
        for name in ["300.pcd", "20.pcd", "notes.txt"] {
            std::fs::write(dir.path().join(name), "")?;
        }
        let scans = list_scans(dir.path())?;
        assert_eq!(
            scans.iter().map(|s| s.stamp_ns).collect::<Vec<_>>(),
            [20, 300]
        );
        std::fs::write(dir.path().join("020.pcd"), "")?;
        let err = list_scans(dir.path()).err().ok_or("expected an error")?;
        assert!(err.to_string().contains("same stamp"), "{err}");
        std::fs::remove_file(dir.path().join("020.pcd"))?;
        std::fs::write(dir.path().join("scan.pcd"), "")?;
        let err = list_scans(dir.path()).err().ok_or("expected an error")?;
        assert!(err.to_string().contains("scan.pcd"), "{err}");
        Ok(())
    }

    #[test]
    fn lidar_yaml_round_trips() -> TestResult {
        let dir = tempfile::tempdir()?;
        let y = LidarYaml {
            rings: Some(64),
            columns: Some(1024),
            scan_rate_hz: Some(10.0),
            range_noise_m: Some(0.02),
        };
        let path = dir.path().join("lidar.yaml");
        y.write(&path)?;
        assert_eq!(LidarYaml::read(&path)?, y);
        Ok(())
    }
}
