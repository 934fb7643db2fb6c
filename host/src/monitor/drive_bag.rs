//! A drive recorded as a ROS 1 bag or an MCAP file, turned into the dataset layout the monitor
//! reads (`imu0/`, `pose0/`, `pose1/`) by the bag converter (`crate::bag`): once for the IMU
//! and the first pose topic, once for the second pose topic, whose `pose0/` becomes `pose1/`.
//! The calibration of record is not in a bag (`msreg monitor --initial`).

use std::path::{Path, PathBuf};

use crate::bag::{self, BagError, ConvertOptions, ConvertSummary, TopicChoice, Topics};
use crate::dataset::{DatasetYaml, ImuNoiseYaml, PoseSensorYaml, DATASET_YAML};

/// Which topics of the bag are the drive's sensors, and the noise files a bag lacks.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DriveTopics {
    /// `sensor_msgs/Imu` topic (default: the only one).
    pub imu: TopicChoice,
    /// The two pose topics (`nav_msgs/Odometry`, `geometry_msgs/PoseStamped` or
    /// `PoseWithCovarianceStamped`): `pose0`, `pose1`.
    pub poses: [String; 2],
    /// `imu0/imu.yaml` (default: `bag::DEFAULT_IMU_NOISE`, warned).
    pub imu_noise: Option<ImuNoiseYaml>,
    /// `pose0/sensor.yaml`, `pose1/sensor.yaml` (default: `bag::DEFAULT_POSE_NOISE`, warned).
    pub pose_noise: [Option<PoseSensorYaml>; 2],
}

/// Converts `path` into the drive dataset `out_dir` (created); `progress` gets the fraction
/// of the two passes read. Returns the two conversions' summaries (IMU + `pose0`; `pose1`,
/// whose stream is reported under `pose0/` by the converter).
pub fn convert_drive(
    path: &Path,
    topics: &DriveTopics,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64),
) -> Result<[ConvertSummary; 2], BagError> {
    let pass = |imu: TopicChoice, k: usize| ConvertOptions {
        topics: Topics {
            imu,
            lidar: TopicChoice::Skip,
            camera: TopicChoice::Skip,
            pose: TopicChoice::Topic(topics.poses[k].clone()),
        },
        imu_noise: topics.imu_noise.clone(),
        pose_noise: topics.pose_noise[k].clone(),
        camera_yaml: None,
        target_yaml: None,
    };
    let first = bag::convert_with(path, &pass(topics.imu.clone(), 0), out_dir, &mut |f| {
        progress(0.5 * f)
    })?;
    let scratch = out_dir.join(".pose1");
    let second = bag::convert_with(path, &pass(TopicChoice::Skip, 1), &scratch, &mut |f| {
        progress(0.5 + 0.5 * f)
    })?;
    let io = |path: PathBuf| move |source| BagError::Io { path, source };
    std::fs::rename(scratch.join("pose0"), out_dir.join("pose1"))
        .map_err(io(out_dir.join("pose1")))?;
    std::fs::remove_dir_all(&scratch).map_err(io(scratch.clone()))?;
    let meta_path = out_dir.join(DATASET_YAML);
    let mut meta = DatasetYaml::read(&meta_path)?;
    meta.sensors.push("pose1".into());
    if let Some(s) = second.streams.first() {
        meta.rates_hz.insert("pose1".into(), s.cadence.rate_hz);
    }
    meta.description.push_str(&format!(
        "; pose0 = {}, pose1 = {}",
        topics.poses[0], topics.poses[1]
    ));
    meta.write(&meta_path)?;
    Ok([first, second])
}
