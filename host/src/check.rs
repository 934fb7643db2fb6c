//! `msreg check`: what is wrong with a dataset before a calibration is tried, named with its
//! numbers (docs/formats.md, "Checking a dataset").
//!
//! [`check_dataset`] reads what is present and returns typed [`Finding`]s, each an error (the
//! calibration cannot succeed or would be wrong), a warning or a note; nothing is printed.
//! The checks, one submodule each:
//! - [`inventory`]: the files the chosen pipeline needs, all missing ones at once;
//! - [`keys`]: unknown keys in the YAML files, with file, line and the likely intended key;
//! - [`streams`]: each stream's span, rate and gaps, and its time overlap with the IMU;
//! - [`units`]: accelerometer in g, gyro in deg/s, target sizes in millimetres;
//! - [`motion`]: each sensor's angular rate against the gyro's (cross-correlation: the clock
//!   offset) and the excitation per axis;
//! - [`scale`]: the camera's metric motion from PnP against the accelerometer's (a wrong
//!   square size scales every PnP translation).

pub mod findings;
pub mod inventory;
pub mod keys;
pub mod motion;
pub mod scale;
pub mod sensors;
pub mod streams;
pub mod units;

use std::path::Path;

pub use findings::{Finding, Severity};
pub use inventory::Needs;

/// What the check found, in the order the checks ran.
#[derive(Debug, Clone, Default)]
pub struct CheckReport {
    /// Every finding.
    pub findings: Vec<Finding>,
}

impl CheckReport {
    /// The findings of one severity.
    pub fn of(&self, severity: Severity) -> impl Iterator<Item = &Finding> {
        self.findings
            .iter()
            .filter(move |f| f.severity() == severity)
    }

    /// Whether any finding is an error.
    pub fn has_errors(&self) -> bool {
        self.of(Severity::Error).next().is_some()
    }
}

/// Checks the dataset directory `root` for a pipeline that needs `needs`; `progress`
/// receives the fraction of corner detection done (the slow part).
pub fn check_dataset(root: &Path, needs: Needs, progress: &(dyn Fn(f64) + Sync)) -> CheckReport {
    let mut findings = Vec::new();
    if !root.is_dir() {
        findings.push(Finding::NoDirectory {
            path: root.to_path_buf(),
        });
        return CheckReport { findings };
    }
    findings.extend(inventory::missing(root, needs));
    findings.extend(keys::unknown_keys(root));
    let data = sensors::load(root, progress);
    findings.extend(data.findings.iter().cloned());
    findings.extend(streams::check(&data));
    let overlapping = !findings
        .iter()
        .any(|f| matches!(f, Finding::NoOverlap { .. }));
    if overlapping {
        findings.extend(motion_checks(&data));
    }
    CheckReport { findings }
}

/// Offsets, excitation and scale, on an IMU in the right units.
fn motion_checks(data: &sensors::SensorData) -> Vec<Finding> {
    let Some(imu) = data.imu.as_deref().filter(|imu| imu.len() > 3) else {
        return Vec::new();
    };
    let gyro = motion::Gyro::new(imu);
    let mut findings = Vec::new();
    let pose0 = motion::pose0_poses(data);
    if pose0.len() > 2 {
        findings.push(motion::time_offset("pose0", &gyro, &pose0).0);
    }
    let cam0 = data
        .camera
        .as_ref()
        .map(motion::camera_poses)
        .unwrap_or_default();
    let mut cam0_offset = None;
    if cam0.len() > 2 {
        let (finding, offset) = motion::time_offset("cam0", &gyro, &cam0);
        findings.push(finding);
        cam0_offset = offset;
    }
    findings.extend(motion::excitation(imu));
    let offset_known = cam0_offset.is_some_and(|o| o.abs() <= findings::MAX_TIME_OFFSET_S);
    if data.target_in_metres && offset_known {
        findings.extend(scale::check(data, &gyro, &cam0, cam0_offset.unwrap_or(0.0)));
    }
    findings
}
