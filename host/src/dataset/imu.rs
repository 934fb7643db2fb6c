//! `imu0/data.csv` (EuRoC IMU rows) and `imu0/imu.yaml` (Kalibr IMU noise).

use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::csv::{read_rows, write_rows};
use super::error::DatasetError;
use super::yaml::{
    check_non_negative, check_positive, read_yaml, write_text, yaml_float, yaml_string,
};

/// One IMU sample in the IMU frame `I`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuRecord {
    /// Sample time, IMU clock, nanoseconds.
    pub stamp_ns: u64,
    /// Angular rate of `I` in `I` [rad/s].
    pub gyro: Vector3<f64>,
    /// Specific force in `I` [m/s^2] (reads +9.81 up when at rest).
    pub accel: Vector3<f64>,
}

const IMU_COLUMNS: &str = "timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]";
const IMU_HEADER: &str = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],\
w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";

/// Reads an EuRoC IMU CSV (`timestamp (ns), w_x, w_y, w_z, a_x, a_y, a_z`).
///
/// Rejects a missing or empty file, wrong column count, NaN/Inf and
/// timestamps that do not strictly increase, naming the file and line.
pub fn read_imu_csv(path: impl AsRef<Path>) -> Result<Vec<ImuRecord>, DatasetError> {
    let rows = read_rows::<6>(path.as_ref(), IMU_COLUMNS)?;
    Ok(rows
        .into_iter()
        .map(|row| {
            let v = row.values;
            ImuRecord {
                stamp_ns: row.stamp_ns,
                gyro: Vector3::new(v[0], v[1], v[2]),
                accel: Vector3::new(v[3], v[4], v[5]),
            }
        })
        .collect())
}

/// Writes an EuRoC IMU CSV with its header line.
pub fn write_imu_csv(path: impl AsRef<Path>, records: &[ImuRecord]) -> Result<(), DatasetError> {
    let rows = records.iter().map(|r| {
        let values = r.gyro.iter().chain(r.accel.iter()).copied().collect();
        (r.stamp_ns, values)
    });
    write_rows(path.as_ref(), IMU_HEADER, rows)
}

/// Kalibr's `imu.yaml`: continuous-time noise densities and bias random walks.
/// Unknown keys are ignored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImuNoiseYaml {
    /// White accelerometer noise [m/s^2/sqrt(Hz)].
    pub accelerometer_noise_density: f64,
    /// Accelerometer bias random walk [m/s^3/sqrt(Hz)].
    pub accelerometer_random_walk: f64,
    /// White gyroscope noise [rad/s/sqrt(Hz)].
    pub gyroscope_noise_density: f64,
    /// Gyroscope bias random walk [rad/s^2/sqrt(Hz)].
    pub gyroscope_random_walk: f64,
    /// Sample rate (Hz).
    pub update_rate: f64,
    /// ROS topic (Kalibr), kept for round trips.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rostopic: Option<String>,
    /// What a sample's value means relative to its stamp (msreg key; absent: instantaneous).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_timing: Option<SampleTiming>,
}

/// How an IMU driver's samples relate to their stamps: `sample_timing` in `imu0/imu.yaml`.
/// The estimator takes every sample as the reading at its stamp; the interval means that
/// integrating IMUs output are re-stamped to their interval's midpoint at load time
/// ([`to_instantaneous`]), which makes them that reading to second order in the period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SampleTiming {
    /// The rate and specific force at the stamp (EuRoC, Kalibr, OpenVINS; the default).
    #[default]
    Instantaneous,
    /// The mean over the sample period that ends at the stamp.
    IntervalMeanEnding,
    /// The mean over the sample period that starts at the stamp.
    IntervalMeanStarting,
}

impl SampleTiming {
    /// The YAML value.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Instantaneous => "instantaneous",
            Self::IntervalMeanEnding => "interval_mean_ending",
            Self::IntervalMeanStarting => "interval_mean_starting",
        }
    }
}

/// Re-stamps interval-mean samples to their interval's midpoint (stamps stay strictly
/// increasing); instantaneous samples are left as they are.
pub fn to_instantaneous(records: &mut [ImuRecord], timing: SampleTiming) {
    let n = records.len();
    if n < 2 || timing == SampleTiming::Instantaneous {
        return;
    }
    let stamps: Vec<u64> = records.iter().map(|r| r.stamp_ns).collect();
    for (k, r) in records.iter_mut().enumerate() {
        r.stamp_ns = match timing {
            SampleTiming::IntervalMeanEnding => {
                let before = if k == 0 {
                    stamps[1] - stamps[0]
                } else {
                    stamps[k] - stamps[k - 1]
                };
                stamps[k].saturating_sub(before / 2)
            }
            _ => {
                let after = if k + 1 == n {
                    stamps[k] - stamps[k - 1]
                } else {
                    stamps[k + 1] - stamps[k]
                };
                stamps[k].saturating_add(after / 2)
            }
        };
    }
}

/// Median |accelerometer| below which the readings are taken to be in g, not m/s^2.
const ACCEL_IN_G_BELOW: f64 = 2.5;
/// A gyro reading above this (rad/s, ~2300 deg/s, beyond MEMS ranges) means deg/s.
const GYRO_IN_DEG_ABOVE: f64 = 40.0;

/// Unit checks of an IMU CSV at load time: an accelerometer in g (median |a| near 1, where
/// gravity alone gives 9.81) or a gyro in deg/s (readings beyond any MEMS range in rad/s)
/// is an error that names the file and the likely unit.
pub fn check_imu_units(path: &Path, records: &[ImuRecord]) -> Result<(), DatasetError> {
    if records.is_empty() {
        return Ok(());
    }
    let mut norms: Vec<f64> = records.iter().map(|r| r.accel.norm()).collect();
    norms.sort_by(f64::total_cmp);
    let median = norms[norms.len() / 2];
    if median < ACCEL_IN_G_BELOW {
        return Err(DatasetError::InvalidValue {
            path: path.to_path_buf(),
            message: format!(
                "median accelerometer magnitude is {median:.3}, where gravity alone reads 9.81 \
                 m/s^2: the accelerometer looks like it is in g; convert the a_x, a_y, a_z \
                 columns to m/s^2 (multiply by 9.80665)"
            ),
        });
    }
    if let Some((line, r)) = records
        .iter()
        .enumerate()
        .find(|(_, r)| r.gyro.amax() > GYRO_IN_DEG_ABOVE)
    {
        return Err(DatasetError::InvalidValue {
            path: path.to_path_buf(),
            message: format!(
                "sample {} (stamp {} ns) has a gyro reading of {:.1}, beyond any MEMS gyro's \
                 range in rad/s: the gyro looks like it is in deg/s; convert the w_x, w_y, w_z \
                 columns to rad/s (multiply by pi/180)",
                line + 1,
                r.stamp_ns,
                r.gyro.amax()
            ),
        });
    }
    Ok(())
}

impl ImuNoiseYaml {
    /// Reads and validates (all values finite, noises >= 0, rate > 0).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let noise: Self = read_yaml(path)?;
        noise.validate(path)?;
        Ok(noise)
    }

    /// Writes Kalibr-compatible YAML.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        write_text(path.as_ref(), &self.to_yaml_string())
    }

    /// The YAML text [`ImuNoiseYaml::write`] writes.
    pub fn to_yaml_string(&self) -> String {
        let mut text = format!(
            "# Kalibr imu.yaml: continuous-time noise densities and bias random walks\n\
             accelerometer_noise_density: {}  # [m/s^2/sqrt(Hz)]\n\
             accelerometer_random_walk: {}  # [m/s^3/sqrt(Hz)]\n\
             gyroscope_noise_density: {}  # [rad/s/sqrt(Hz)]\n\
             gyroscope_random_walk: {}  # [rad/s^2/sqrt(Hz)]\n\
             update_rate: {}  # [Hz]\n",
            yaml_float(self.accelerometer_noise_density),
            yaml_float(self.accelerometer_random_walk),
            yaml_float(self.gyroscope_noise_density),
            yaml_float(self.gyroscope_random_walk),
            yaml_float(self.update_rate),
        );
        if let Some(topic) = &self.rostopic {
            text.push_str(&format!("rostopic: {}\n", yaml_string(topic)));
        }
        if let Some(timing) = self.sample_timing {
            text.push_str(&format!("sample_timing: {}\n", timing.as_str()));
        }
        text
    }

    fn validate(&self, path: &Path) -> Result<(), DatasetError> {
        check_non_negative(
            path,
            "accelerometer_noise_density",
            self.accelerometer_noise_density,
        )?;
        check_non_negative(
            path,
            "accelerometer_random_walk",
            self.accelerometer_random_walk,
        )?;
        check_non_negative(
            path,
            "gyroscope_noise_density",
            self.gyroscope_noise_density,
        )?;
        check_non_negative(path, "gyroscope_random_walk", self.gyroscope_random_walk)?;
        check_positive(path, "update_rate", self.update_rate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    fn write_file(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, text).ok();
        path
    }

    #[test]
    fn missing_file_names_the_path() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("nope.csv");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(&err, DatasetError::MissingFile { path: p } if *p == path));
        assert!(err.to_string().contains("nope.csv"));
        Ok(())
    }

    #[test]
    fn euroc_file_with_header_and_spaces_is_read() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(
            &dir,
            "imu.csv",
            "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y,w_RS_S_z,a_x,a_y,a_z\n\
             1403636579758555392, -0.0991, 0.1382,0.0268 ,8.1,-0.3 , -2.4\r\n\
             1403636579763555584,-0.1,0.13,0.02,8.2,-0.4,-2.5\n\n",
        );
        let records = read_imu_csv(&path)?;
        assert_eq!(records.len(), 2);
        assert_eq!(records[0].stamp_ns, 1_403_636_579_758_555_392);
        assert!((records[0].accel.z + 2.4).abs() < 1e-15);
        assert!((records[1].gyro.x + 0.1).abs() < 1e-15);
        Ok(())
    }

    #[test]
    fn wrong_column_count_reports_the_line() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(
            &dir,
            "imu.csv",
            "#header\n1,0,0,0,0,0,9.81\n2,0,0,0,0,9.81\n",
        );
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::MalformedLine { line: 3, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("imu.csv:3"), "{err}");
        assert!(err.to_string().contains("found 6"), "{err}");
        Ok(())
    }

    #[test]
    fn nan_is_rejected_with_line_and_column() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(&dir, "imu.csv", "1,0,0,0,0,0,9.81\n2,0,NaN,0,0,0,9.81\n");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(
                err,
                DatasetError::NonFinite {
                    line: 2,
                    column: 3,
                    ..
                }
            ),
            "{err}"
        );
        let path = write_file(&dir, "inf.csv", "1,0,0,0,0,0,inf\n");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::NonFinite { line: 1, .. }),
            "{err}"
        );
        Ok(())
    }

    #[test]
    fn time_going_backwards_or_repeating_is_rejected() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(&dir, "imu.csv", "#h\n10,0,0,0,0,0,1\n9,0,0,0,0,0,1\n");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(
                err,
                DatasetError::TimeNotIncreasing {
                    line: 3,
                    stamp_ns: 9,
                    previous_ns: 10,
                    ..
                }
            ),
            "{err}"
        );
        let path = write_file(&dir, "rep.csv", "10,0,0,0,0,0,1\n10,0,0,0,0,0,1\n");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(
            err,
            DatasetError::TimeNotIncreasing { line: 2, .. }
        ));
        Ok(())
    }

    #[test]
    fn non_numeric_field_and_empty_file_are_rejected() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(&dir, "imu.csv", "1,0,0,x,0,0,1\n");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::MalformedLine { line: 1, .. }));
        let path = write_file(&dir, "empty.csv", "#only a header\n");
        let err = read_imu_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::Empty { .. }));
        Ok(())
    }

    #[test]
    fn imu_csv_round_trips_exactly() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("imu.csv");
        let records = vec![
            ImuRecord {
                stamp_ns: 1_700_000_000_000_000_000,
                gyro: Vector3::new(0.1, -1e-9, 1.234_567_890_123_456_7),
                accel: Vector3::new(-9.81, 1e-20, 3.0),
            },
            ImuRecord {
                stamp_ns: 1_700_000_000_002_500_000,
                gyro: Vector3::new(0.0, 2.0, -3.5),
                accel: Vector3::new(0.3, 0.2, 9.9),
            },
        ];
        write_imu_csv(&path, &records)?;
        assert_eq!(read_imu_csv(&path)?, records);
        Ok(())
    }

    #[test]
    fn imu_yaml_tolerates_kalibr_keys_and_round_trips() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(
            &dir,
            "imu.yaml",
            "#Accelerometers\naccelerometer_noise_density: 1.86e-03\n\
             accelerometer_random_walk: 4.33e-04\ngyroscope_noise_density: 1.87e-04\n\
             gyroscope_random_walk: 2.66e-05\nrostopic: /imu0\nupdate_rate: 200.0\n\
             some_future_key: [1, 2]\n",
        );
        let noise = ImuNoiseYaml::read(&path)?;
        assert!((noise.gyroscope_random_walk - 2.66e-5).abs() < 1e-20);
        assert_eq!(noise.rostopic.as_deref(), Some("/imu0"));
        let out = dir.path().join("out.yaml");
        noise.write(&out)?;
        assert_eq!(ImuNoiseYaml::read(&out)?, noise);
        Ok(())
    }

    #[test]
    fn bad_imu_yaml_reports_line_and_column() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = write_file(
            &dir,
            "imu.yaml",
            "accelerometer_noise_density: 1.0e-3\naccelerometer_random_walk: [oops\n",
        );
        let err = ImuNoiseYaml::read(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::Yaml { line: Some(_), .. }),
            "{err}"
        );
        assert!(err.to_string().contains("imu.yaml:"), "{err}");

        let path = write_file(&dir, "missing_key.yaml", "update_rate: 200.0\n");
        let err = ImuNoiseYaml::read(&path).err().ok_or("expected an error")?;
        assert!(
            err.to_string().contains("accelerometer_noise_density"),
            "{err}"
        );

        let path = write_file(
            &dir,
            "negative.yaml",
            "accelerometer_noise_density: -1.0\naccelerometer_random_walk: 1.0\n\
             gyroscope_noise_density: 1.0\ngyroscope_random_walk: 1.0\nupdate_rate: 200\n",
        );
        let err = ImuNoiseYaml::read(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::InvalidValue { .. }), "{err}");
        Ok(())
    }
}
