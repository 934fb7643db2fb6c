//! A drive recorded as a ROS 1 bag or an MCAP file, turned into the dataset layout the monitor
//! reads (`imu0/`, `pose0/`, `pose1/`, ...) by the bag converter (`crate::bag`): once for the
//! IMU and the first pose topic, then once per further pose topic, whose `pose0/` becomes
//! `poseK/`. The calibration of record is not in a bag (`msreg monitor --initial`).

use std::path::{Path, PathBuf};

use crate::bag::{self, BagError, ConvertOptions, ConvertSummary, TopicChoice, Topics};
use crate::dataset::{DatasetYaml, ImuNoiseYaml, PoseSensorYaml, DATASET_YAML};

/// Which topics of the bag are the drive's sensors, and the noise files a bag lacks.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DriveTopics {
    /// `sensor_msgs/Imu` topic (default: the only one).
    pub imu: TopicChoice,
    /// The pose topics (`nav_msgs/Odometry`, `geometry_msgs/PoseStamped` or
    /// `PoseWithCovarianceStamped`): `pose0`, `pose1`, ... (at least one).
    pub poses: Vec<String>,
    /// `imu0/imu.yaml` (default: `bag::DEFAULT_IMU_NOISE`, warned).
    pub imu_noise: Option<ImuNoiseYaml>,
    /// `poseK/sensor.yaml` per pose topic (default, and where the list is short:
    /// `bag::DEFAULT_POSE_NOISE`, warned).
    pub pose_noise: Vec<Option<PoseSensorYaml>>,
}

/// Converts `path` into the drive dataset `out_dir` (created); `progress` gets the fraction
/// of the passes read. Returns each pass's summary (IMU + `pose0`; then `poseK`, whose stream
/// is reported under `pose0/` by the converter).
pub fn convert_drive(
    path: &Path,
    topics: &DriveTopics,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64),
) -> Result<Vec<ConvertSummary>, BagError> {
    let pass = |imu: TopicChoice, k: usize| ConvertOptions {
        topics: Topics {
            imu,
            lidar: TopicChoice::Skip,
            camera: TopicChoice::Skip,
            pose: TopicChoice::Topic(topics.poses[k].clone()),
        },
        imu_noise: topics.imu_noise.clone(),
        pose_noise: topics.pose_noise.get(k).cloned().flatten(),
        camera_yaml: None,
        target_yaml: None,
    };
    let passes = topics.poses.len().max(1) as f64;
    let mut summaries = vec![bag::convert_with(
        path,
        &pass(topics.imu.clone(), 0),
        out_dir,
        &mut |f| progress(f / passes),
    )?];
    let io = |path: PathBuf| move |source| BagError::Io { path, source };
    let meta_path = out_dir.join(DATASET_YAML);
    let mut meta = DatasetYaml::read(&meta_path)?;
    for k in 1..topics.poses.len() {
        let name = format!("pose{k}");
        let scratch = out_dir.join(format!(".{name}"));
        let summary = bag::convert_with(path, &pass(TopicChoice::Skip, k), &scratch, &mut |f| {
            progress((k as f64 + f) / passes)
        })?;
        std::fs::rename(scratch.join("pose0"), out_dir.join(&name))
            .map_err(io(out_dir.join(&name)))?;
        std::fs::remove_dir_all(&scratch).map_err(io(scratch.clone()))?;
        meta.sensors.push(name.clone());
        if let Some(s) = summary.streams.first() {
            meta.rates_hz.insert(name, s.cadence.rate_hz);
        }
        summaries.push(summary);
    }
    let names: Vec<String> = topics
        .poses
        .iter()
        .enumerate()
        .map(|(k, t)| format!("pose{k} = {t}"))
        .collect();
    meta.description
        .push_str(&format!("; {}", names.join(", ")));
    meta.write(&meta_path)?;
    Ok(summaries)
}
