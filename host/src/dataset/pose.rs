//! `pose0/data.csv` (odometry `T_odom_S` of a generic pose sensor S) and
//! `pose0/sensor.yaml` (1-sigma noise of one odometry increment).

use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::csv::{read_rows, write_rows};
use super::error::DatasetError;
use super::yaml::{check_non_negative, check_positive, read_yaml, write_text, yaml_float};

/// One pose `T_odom_S` of the sensor in its own odometry frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseRecord {
    /// Measurement stamp, sensor clock, nanoseconds.
    pub stamp_ns: u64,
    /// `p_odom_S` (m).
    pub position: Vector3<f64>,
    /// `R_odom_S` (Hamilton).
    pub rotation: UnitQuaternion<f64>,
}

impl PoseRecord {
    /// The pose as an isometry `T_odom_S`.
    pub fn isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.position), self.rotation)
    }

    /// A record from a stamp and an isometry.
    pub fn from_isometry(stamp_ns: u64, pose: &Isometry3<f64>) -> Self {
        Self {
            stamp_ns,
            position: pose.translation.vector,
            rotation: pose.rotation,
        }
    }
}

const POSE_COLUMNS: &str = "timestamp [ns], p_x, p_y, p_z [m], q_w, q_x, q_y, q_z";
const POSE_HEADER: &str = "#timestamp [ns],p_x [m],p_y [m],p_z [m],q_w [],q_x [],q_y [],q_z []";

/// Tolerance on the norm of a stored quaternion before it is normalised.
const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;
/// A norm this close to 1 is unit up to rounding and is kept as stored.
const ALREADY_UNIT: f64 = 1e-12;

/// Reads `pose0/data.csv`: `timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z`.
///
/// Quaternions further than 1e-3 from unit norm are an error (likely a
/// column mix-up); others are normalised.
pub fn read_pose_csv(path: impl AsRef<Path>) -> Result<Vec<PoseRecord>, DatasetError> {
    let path = path.as_ref();
    read_rows::<7>(path, POSE_COLUMNS)?
        .into_iter()
        .map(|row| {
            let v = row.values;
            Ok(PoseRecord {
                stamp_ns: row.stamp_ns,
                position: Vector3::new(v[0], v[1], v[2]),
                rotation: unit_quaternion_wxyz(path, row.line, [v[3], v[4], v[5], v[6]])?,
            })
        })
        .collect()
}

/// Writes `pose0/data.csv` with its header line.
pub fn write_pose_csv(path: impl AsRef<Path>, records: &[PoseRecord]) -> Result<(), DatasetError> {
    let rows = records.iter().map(|r| {
        let mut values: Vec<f64> = r.position.iter().copied().collect();
        values.extend(quaternion_wxyz(&r.rotation));
        (r.stamp_ns, values)
    });
    write_rows(path.as_ref(), POSE_HEADER, rows)
}

/// A unit quaternion from stored `w, x, y, z`, checking the norm.
pub(crate) fn unit_quaternion_wxyz(
    path: &Path,
    line: usize,
    wxyz: [f64; 4],
) -> Result<UnitQuaternion<f64>, DatasetError> {
    let q = Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(DatasetError::NonUnitQuaternion {
            path: path.to_path_buf(),
            line,
            norm,
        });
    }
    if (norm - 1.0).abs() <= ALREADY_UNIT {
        // Keep the stored digits: writing and reading back is then exact.
        Ok(UnitQuaternion::new_unchecked(q))
    } else {
        Ok(UnitQuaternion::new_normalize(q))
    }
}

/// `[w, x, y, z]` of a unit quaternion, the column order of the files.
pub(crate) fn quaternion_wxyz(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// `pose0/sensor.yaml`: 1-sigma noise of one odometry increment.
/// Unknown keys are ignored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseSensorYaml {
    /// Rotation noise of one increment, per axis (rad).
    pub rotation_noise_rad: f64,
    /// Translation noise of one increment, per axis (m).
    pub translation_noise_m: f64,
    /// Nominal pose rate (Hz), informative.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
}

impl PoseSensorYaml {
    /// Reads and validates (noises finite and >= 0, rate > 0 when given).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let sensor: Self = read_yaml(path)?;
        check_non_negative(path, "rotation_noise_rad", sensor.rotation_noise_rad)?;
        check_non_negative(path, "translation_noise_m", sensor.translation_noise_m)?;
        if let Some(rate) = sensor.rate_hz {
            check_positive(path, "rate_hz", rate)?;
        }
        Ok(sensor)
    }

    /// Writes the YAML file.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        write_text(path.as_ref(), &self.to_yaml_string())
    }

    /// The YAML text [`PoseSensorYaml::write`] writes.
    pub fn to_yaml_string(&self) -> String {
        let mut text = format!(
            "# 1-sigma noise of one odometry increment, per axis\n\
             rotation_noise_rad: {}\ntranslation_noise_m: {}\n",
            yaml_float(self.rotation_noise_rad),
            yaml_float(self.translation_noise_m),
        );
        if let Some(rate) = self.rate_hz {
            text.push_str(&format!("rate_hz: {}\n", yaml_float(rate)));
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    #[test]
    fn pose_csv_round_trips_and_normalises() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("data.csv");
        let records = vec![
            PoseRecord {
                stamp_ns: 5,
                position: Vector3::new(1.0, -2.0, 0.125),
                rotation: UnitQuaternion::from_euler_angles(0.1, -0.2, 3.0),
            },
            PoseRecord {
                stamp_ns: 7,
                position: Vector3::new(1e-9, 0.0, 1e7),
                rotation: UnitQuaternion::identity(),
            },
        ];
        write_pose_csv(&path, &records)?;
        assert_eq!(read_pose_csv(&path)?, records);

        std::fs::write(&path, "1,0,0,0,1.0005,0,0,0\n")?;
        let read = read_pose_csv(&path)?;
        assert!((read[0].rotation.quaternion().norm() - 1.0).abs() < 1e-15);
        Ok(())
    }

    #[test]
    fn non_unit_quaternion_is_rejected_with_line() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("data.csv");
        std::fs::write(&path, "#h\n1,0,0,0,1,0,0,0\n2,0,0,0,0.5,0,0,0\n")?;
        let err = read_pose_csv(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::NonUnitQuaternion { line: 3, .. }),
            "{err}"
        );
        Ok(())
    }

    #[test]
    fn pose_csv_error_paths() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("data.csv");
        let err = read_pose_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::MissingFile { .. }));
        std::fs::write(&path, "1,0,0,0,1,0,0,0\n2,0,0,0,1,0,0\n")?;
        let err = read_pose_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::MalformedLine { line: 2, .. }));
        std::fs::write(&path, "1,0,0,nan,1,0,0,0\n")?;
        let err = read_pose_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(
            err,
            DatasetError::NonFinite {
                line: 1,
                column: 4,
                ..
            }
        ));
        std::fs::write(&path, "2,0,0,0,1,0,0,0\n1,0,0,0,1,0,0,0\n")?;
        let err = read_pose_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(
            err,
            DatasetError::TimeNotIncreasing { line: 2, .. }
        ));
        Ok(())
    }

    #[test]
    fn sensor_yaml_round_trips_and_rejects_bad_values() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("sensor.yaml");
        let sensor = PoseSensorYaml {
            rotation_noise_rad: 0.003_490_658_503_988_659,
            translation_noise_m: 0.005,
            rate_hz: Some(10.0),
        };
        sensor.write(&path)?;
        assert_eq!(PoseSensorYaml::read(&path)?, sensor);

        std::fs::write(
            &path,
            "rotation_noise_rad: 0.1\ntranslation_noise_m: .nan\n",
        )?;
        let err = PoseSensorYaml::read(&path)
            .err()
            .ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::InvalidValue { .. }), "{err}");

        std::fs::write(&path, "rotation_noise_rad: 0.1\ntranslation_noise_m: abc\n")?;
        let err = PoseSensorYaml::read(&path)
            .err()
            .ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::Yaml { line: Some(2), .. }),
            "{err}"
        );
        Ok(())
    }
}
