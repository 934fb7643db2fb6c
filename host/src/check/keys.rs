//! Unknown keys in the dataset's YAML files: each is ignored by its reader, so a typo (say
//! `distortion_coefs`) silently drops a value. Each is named with file, line and the known
//! key it is closest to.

use std::path::Path;

use serde_yaml::{Mapping, Value};

use super::Finding;
use crate::dataset::{CAMERA_YAML, IMU_YAML, POSE_SENSOR_YAML, TARGET_YAML};

/// Keys of `camN/camera.yaml` (a Kalibr camchain entry; the extrinsic keys are accepted
/// and ignored).
const CAMERA_KEYS: &[&str] = &[
    "camera_model",
    "intrinsics",
    "distortion_model",
    "distortion_coeffs",
    "resolution",
    "rostopic",
    "cam_overlaps",
    "T_cn_cnm1",
    "T_cam_imu",
    "timeshift_cam_imu",
];
/// Keys of `target.yaml` (Kalibr's, plus the physical board).
const TARGET_KEYS: &[&str] = &[
    "target_type",
    "targetRows",
    "targetCols",
    "rowSpacingMeters",
    "colSpacingMeters",
    "tagRows",
    "tagCols",
    "tagSize",
    "tagSpacing",
    "codeOffset",
    "width_m",
    "height_m",
];
/// Keys of `imuN/imu.yaml`.
const IMU_KEYS: &[&str] = &[
    "accelerometer_noise_density",
    "accelerometer_random_walk",
    "gyroscope_noise_density",
    "gyroscope_random_walk",
    "update_rate",
    "rostopic",
    "sample_timing",
];
/// Keys of `poseN/sensor.yaml`.
const POSE_KEYS: &[&str] = &["rotation_noise_rad", "translation_noise_m", "rate_hz"];

/// Unknown keys of every YAML file present (files that do not parse are left to their
/// readers, whose errors name the line).
pub fn unknown_keys(root: &Path) -> Vec<Finding> {
    let files: [(&str, &[&str]); 4] = [
        (CAMERA_YAML, CAMERA_KEYS),
        (TARGET_YAML, TARGET_KEYS),
        (IMU_YAML, IMU_KEYS),
        (POSE_SENSOR_YAML, POSE_KEYS),
    ];
    files
        .iter()
        .flat_map(|(file, known)| unknown_in(&root.join(file), known))
        .collect()
}

/// The unknown top-level keys of one file (inside a single `camN:` wrapper for a camera).
pub fn unknown_in(path: &Path, known: &'static [&'static str]) -> Vec<Finding> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    let Ok(Value::Mapping(root)) = serde_yaml::from_str::<Value>(&text) else {
        return Vec::new();
    };
    let map: &Mapping = match (root.len(), root.iter().next()) {
        (1, Some((Value::String(k), Value::Mapping(inner)))) if !known.contains(&k.as_str()) => {
            inner
        }
        _ => &root,
    };
    map.keys()
        .filter_map(Value::as_str)
        .filter(|k| !known.contains(k))
        .map(|key| Finding::UnknownKey {
            path: path.to_path_buf(),
            line: line_of(&text, key),
            key: key.to_string(),
            suggestion: closest(key, known),
        })
        .collect()
}

/// 1-based line of `key:` (first occurrence; 1 when not found verbatim).
pub(super) fn line_of(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            let t = l.trim_start().trim_start_matches(['"', '\'']);
            t.strip_prefix(key)
                .is_some_and(|rest| rest.trim_start_matches(['"', '\'']).starts_with(':'))
        })
        .map_or(1, |i| i + 1)
}

/// The known key within a small edit distance (a third of its length, at least 2).
fn closest(key: &str, known: &'static [&'static str]) -> Option<&'static str> {
    let lower = key.to_lowercase();
    known
        .iter()
        .map(|k| (edit_distance(&lower, &k.to_lowercase()), *k))
        .filter(|(d, k)| *d <= (k.len() / 3).max(2))
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

/// Levenshtein distance.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitution = diagonal + usize::from(ca != *cb);
            diagonal = row[j + 1];
            row[j + 1] = substitution.min(row[j] + 1).min(row[j + 1] + 1);
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_typo_is_named_with_its_line_and_the_intended_key() -> Result<(), std::io::Error> {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("camera.yaml");
        std::fs::write(
            &path,
            "camera_model: pinhole\nintrinsics: [1, 1, 0, 0]\ndistortion_model: radtan\n\
             distortion_coefs: [0, 0, 0, 0]\nresolution: [640, 480]\n",
        )?;
        let found = unknown_in(&path, CAMERA_KEYS);
        assert_eq!(
            found,
            vec![Finding::UnknownKey {
                path: path.clone(),
                line: 4,
                key: "distortion_coefs".into(),
                suggestion: Some("distortion_coeffs"),
            }]
        );
        assert_eq!(closest("banana", CAMERA_KEYS), None);
        Ok(())
    }
}
