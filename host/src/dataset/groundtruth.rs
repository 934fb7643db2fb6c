//! `groundtruth/trajectory.csv`: EuRoC ground-truth rows (pose of `I` in `G`,
//! velocity in `G`, gyroscope and accelerometer biases in `I`), written by the
//! simulator and read by `msreg eval` and the tests.

use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::csv::{read_rows, write_rows};
use super::error::DatasetError;
use super::pose::{quaternion_wxyz, unit_quaternion_wxyz};

/// One ground-truth state of the IMU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundTruthRecord {
    /// IMU time, nanoseconds.
    pub stamp_ns: u64,
    /// `p_G_I` (m).
    pub position: Vector3<f64>,
    /// `R_G_I` (Hamilton).
    pub rotation: UnitQuaternion<f64>,
    /// `v_G_I`, velocity of `I` in `G` [m/s].
    pub velocity: Vector3<f64>,
    /// Gyroscope bias in `I` [rad/s].
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer bias in `I` [m/s^2].
    pub accel_bias: Vector3<f64>,
}

impl GroundTruthRecord {
    /// The pose `T_G_I`.
    pub fn isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.position), self.rotation)
    }
}

const GT_COLUMNS: &str = "timestamp [ns], p_RS_R_x, p_RS_R_y, p_RS_R_z, q_RS_w, q_RS_x, q_RS_y, \
q_RS_z, v_RS_R_x, v_RS_R_y, v_RS_R_z, b_w_RS_S_x, b_w_RS_S_y, b_w_RS_S_z, b_a_RS_S_x, b_a_RS_S_y, \
b_a_RS_S_z";
const GT_HEADER: &str = "#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],\
q_RS_y [],q_RS_z [],v_RS_R_x [m s^-1],v_RS_R_y [m s^-1],v_RS_R_z [m s^-1],\
b_w_RS_S_x [rad s^-1],b_w_RS_S_y [rad s^-1],b_w_RS_S_z [rad s^-1],\
b_a_RS_S_x [m s^-2],b_a_RS_S_y [m s^-2],b_a_RS_S_z [m s^-2]";

/// Reads EuRoC ground truth (17 columns); quaternions as in [`super::read_pose_csv`].
pub fn read_groundtruth_csv(
    path: impl AsRef<Path>,
) -> Result<Vec<GroundTruthRecord>, DatasetError> {
    let path = path.as_ref();
    read_rows::<16>(path, GT_COLUMNS)?
        .into_iter()
        .map(|row| {
            let v = row.values;
            Ok(GroundTruthRecord {
                stamp_ns: row.stamp_ns,
                position: Vector3::new(v[0], v[1], v[2]),
                rotation: unit_quaternion_wxyz(path, row.line, [v[3], v[4], v[5], v[6]])?,
                velocity: Vector3::new(v[7], v[8], v[9]),
                gyro_bias: Vector3::new(v[10], v[11], v[12]),
                accel_bias: Vector3::new(v[13], v[14], v[15]),
            })
        })
        .collect()
}

/// Writes EuRoC ground truth with its header line.
pub fn write_groundtruth_csv(
    path: impl AsRef<Path>,
    records: &[GroundTruthRecord],
) -> Result<(), DatasetError> {
    let rows = records.iter().map(|r| {
        let mut values: Vec<f64> = r.position.iter().copied().collect();
        values.extend(quaternion_wxyz(&r.rotation));
        values.extend(r.velocity.iter());
        values.extend(r.gyro_bias.iter());
        values.extend(r.accel_bias.iter());
        (r.stamp_ns, values)
    });
    write_rows(path.as_ref(), GT_HEADER, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    fn record(stamp_ns: u64) -> GroundTruthRecord {
        GroundTruthRecord {
            stamp_ns,
            position: Vector3::new(0.1, 0.2, 1.3),
            rotation: UnitQuaternion::from_euler_angles(3.0, 0.1, -1.0),
            velocity: Vector3::new(-0.5, 0.25, 1e-12),
            gyro_bias: Vector3::new(1e-3, -2e-4, 0.0),
            accel_bias: Vector3::new(0.02, 0.01, -0.03),
        }
    }

    #[test]
    fn groundtruth_round_trips_exactly() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("trajectory.csv");
        let records = vec![record(10), record(20), record(30)];
        write_groundtruth_csv(&path, &records)?;
        assert_eq!(read_groundtruth_csv(&path)?, records);
        Ok(())
    }

    #[test]
    fn groundtruth_error_paths() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("trajectory.csv");
        let err = read_groundtruth_csv(&path)
            .err()
            .ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::MissingFile { .. }));
        std::fs::write(&path, "#h\n1,0,0,0,1,0,0,0\n")?;
        let err = read_groundtruth_csv(&path)
            .err()
            .ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::MalformedLine { line: 2, .. }),
            "{err}"
        );
        assert!(
            err.to_string().contains("17 comma-separated columns"),
            "{err}"
        );
        Ok(())
    }
}
