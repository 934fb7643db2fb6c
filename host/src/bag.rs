//! ROS bags and MCAP files in: a ROS 1 `.bag` (rosbag crate) or a ROS 2 / any `.mcap`
//! (mcap crate) converted to the dataset directory layout of docs/formats.md, so every
//! pipeline reads a recording as it reads a directory.
//!
//! Messages are decoded by hand from the ROS 1 wire format or CDR ([`wire`], [`msgs`]), no
//! ROS install: `sensor_msgs/Imu` -> `imu0/`, `sensor_msgs/PointCloud2` -> `lidar0/`
//! (per-point time from `t`/`time`/`timestamp`/`offset_time`, see [`cloud`]),
//! `sensor_msgs/Image` / `CompressedImage` -> `cam0/`, `nav_msgs/Odometry` /
//! `geometry_msgs/PoseStamped` / `PoseWithCovarianceStamped` -> `pose0/`. Stamps are the
//! messages' header stamps (the bag's receive time only where a header stamp is zero).
//!
//! A bag carries no noise figures: `imu0/imu.yaml` and `pose0/sensor.yaml` come from
//! [`ConvertOptions`] or are the documented defaults ([`DEFAULT_IMU_NOISE`],
//! [`DEFAULT_POSE_NOISE`]) with a warning. What looks wrong but does not stop the
//! conversion is returned as typed [`BagWarning`]s; what stops it is a [`BagError`].

pub mod cloud;
mod error;
pub mod image;
pub mod msgs;
mod sink;
pub mod source;
pub mod topics;
mod warnings;
pub mod wire;

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use cloud::{PointTime, TimeUnit};
pub use error::{BagError, DecodeError};
pub use source::{BagFile, BagFormat, TopicInfo};
pub use topics::{Role, TopicChoice, Topics};
pub use warnings::{BagWarning, Cadence};

use crate::dataset::{
    write_camera_csv, write_imu_csv, write_pose_csv, DatasetYaml, ImuNoiseYaml, LidarYaml,
    PoseSensorYaml, CAMERA_CSV, CAMERA_DATA_DIR, CAMERA_YAML, DATASET_YAML, IMU_CSV, IMU_YAML,
    LIDAR_YAML, POSE_CSV, POSE_SENSOR_YAML, TARGET_YAML,
};
use msreg_estimator::{FilterConfig, ImuNoise};
use sink::Sink;
use warnings::{cadence, long_intervals, sort_stamped};

/// `imu0/imu.yaml` written when no `--imu-config` is given: EuRoC's published ADIS16448
/// figures (a mid-grade MEMS IMU; `update_rate` is replaced by the measured rate).
pub const DEFAULT_IMU_NOISE: ImuNoiseYaml = ImuNoiseYaml {
    accelerometer_noise_density: 2.0e-3,
    accelerometer_random_walk: 3.0e-3,
    gyroscope_noise_density: 1.6968e-4,
    gyroscope_random_walk: 1.9393e-5,
    update_rate: 200.0,
    rostopic: None,
    sample_timing: None,
};

/// `pose0/sensor.yaml` written when no `--pose-config` is given: 1-sigma noise of one
/// odometry increment, 0.2 deg and 5 mm per axis.
pub const DEFAULT_POSE_NOISE: PoseSensorYaml = PoseSensorYaml {
    rotation_noise_rad: 3.5e-3,
    translation_noise_m: 5e-3,
    rate_hz: None,
};

/// The IMU rate below which a warning says the pipelines are outside their design, Hz.
const LOW_IMU_RATE_HZ: f64 = 100.0;

/// Everything a conversion is told besides the bag and the output directory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConvertOptions {
    /// Topic of each sensor.
    pub topics: Topics,
    /// `imu0/imu.yaml` (Kalibr keys; `update_rate` kept as given). `None`: defaults + warning.
    pub imu_noise: Option<ImuNoiseYaml>,
    /// `pose0/sensor.yaml`. `None`: defaults + warning.
    pub pose_noise: Option<PoseSensorYaml>,
    /// Copied to `cam0/camera.yaml` when a camera topic is converted.
    pub camera_yaml: Option<PathBuf>,
    /// Copied to `target.yaml` when a camera topic is converted.
    pub target_yaml: Option<PathBuf>,
}

/// One converted stream.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StreamSummary {
    /// The sensor it became.
    pub role: Role,
    /// Topic.
    pub topic: String,
    /// Message type.
    pub msg_type: String,
    /// `frame_id` of the first message.
    pub frame_id: String,
    /// Odometry's `child_frame_id` (the moving frame), empty for the other types.
    pub child_frame_id: String,
    /// Records written (after sorting and dropping duplicates).
    pub written: usize,
    /// First and last stamp, ns.
    pub first_last_ns: (u64, u64),
    /// Interval statistics.
    pub cadence: Cadence,
}

/// What [`convert`] did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ConvertSummary {
    /// Container format.
    pub format: BagFormat,
    /// The converted streams.
    pub streams: Vec<StreamSummary>,
    /// How the LiDAR's per-point time was read (when a LiDAR topic was converted).
    pub lidar_time: Option<PointTime>,
    /// The IMU noise written.
    pub imu_noise: Option<ImuNoiseYaml>,
    /// Sanity-check findings.
    pub warnings: Vec<BagWarning>,
}

/// Converts the bag or MCAP file `path` into a dataset directory `out_dir` (created),
/// default noise figures; `progress` gets the fraction of the file read.
pub fn convert(
    path: &Path,
    topics: &Topics,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64),
) -> Result<ConvertSummary, BagError> {
    let options = ConvertOptions {
        topics: topics.clone(),
        ..ConvertOptions::default()
    };
    convert_with(path, &options, out_dir, progress)
}

/// [`convert`] with noise figures and camera files.
pub fn convert_with(
    path: &Path,
    options: &ConvertOptions,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64),
) -> Result<ConvertSummary, BagError> {
    let bag = BagFile::open(path)?;
    let infos = bag.topics(path)?;
    let mut warnings = Vec::new();
    let selected = topics::select(path, &infos, &options.topics, &mut warnings)?;
    if selected.is_empty() {
        return Err(BagError::NothingToConvert {
            path: path.to_path_buf(),
            available: infos.iter().map(TopicInfo::describe).collect(),
        });
    }
    for s in &selected {
        let dir = match s.role {
            Role::Camera => out_dir.join(CAMERA_DATA_DIR),
            role => out_dir.join(role.sensor()),
        };
        create_dir(&dir)?;
    }
    let wanted = selected.iter().map(|s| s.topic.clone()).collect();
    let mut sink = Sink::new(path, out_dir, &selected);
    bag.for_each(
        path,
        &wanted,
        &mut |topic, time, data| sink.accept(topic, time, data),
        progress,
    )?;
    sink.count_warnings();
    warnings.append(&mut sink.warnings);
    let mut summary = ConvertSummary {
        format: bag.format(),
        streams: Vec::new(),
        lidar_time: None,
        imu_noise: None,
        warnings,
    };
    for s in &selected {
        let stream = finish_role(s, &mut sink, options, out_dir, &mut summary)?;
        summary.streams.push(stream);
    }
    write_dataset_yaml(path, out_dir, &summary)?;
    Ok(summary)
}

fn create_dir(dir: &Path) -> Result<(), BagError> {
    std::fs::create_dir_all(dir).map_err(|source| BagError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

/// Sorts, checks and writes one role's files.
fn finish_role(
    s: &topics::Selected,
    sink: &mut Sink<'_>,
    options: &ConvertOptions,
    out: &Path,
    summary: &mut ConvertSummary,
) -> Result<StreamSummary, BagError> {
    let w = &mut summary.warnings;
    let stamps: Vec<u64> = match s.role {
        Role::Imu => {
            sort_stamped(&s.topic, &mut sink.imu, w);
            let records: Vec<_> = sink.imu.iter().map(|(_, r)| *r).collect();
            write_imu_csv(out.join(IMU_CSV), &records)?;
            records.iter().map(|r| r.stamp_ns).collect()
        }
        Role::Pose => {
            sort_stamped(&s.topic, &mut sink.poses, w);
            let records: Vec<_> = sink.poses.iter().map(|(_, r)| *r).collect();
            write_pose_csv(out.join(POSE_CSV), &records)?;
            records.iter().map(|r| r.stamp_ns).collect()
        }
        Role::Lidar => {
            sort_stamped(&s.topic, &mut sink.scans, w);
            sink.scans.iter().map(|(t, _)| *t).collect()
        }
        Role::Camera => {
            sort_stamped(&s.topic, &mut sink.images, w);
            let frames: Vec<_> = sink.images.iter().map(|(_, f)| f.clone()).collect();
            write_camera_csv(out.join(CAMERA_CSV), &frames)?;
            frames.iter().map(|f| f.stamp_ns).collect()
        }
    };
    let cadence = cadence(&s.topic, &stamps, w);
    match s.role {
        Role::Imu => summary.imu_noise = Some(finish_imu(s, sink, options, out, cadence, w)?),
        Role::Pose => finish_pose(options, out, cadence, w)?,
        Role::Lidar => summary.lidar_time = finish_lidar(s, sink, out, cadence, w)?,
        Role::Camera => finish_camera(options, out, w)?,
    }
    Ok(StreamSummary {
        role: s.role,
        topic: s.topic.clone(),
        msg_type: s.msg_type.clone(),
        frame_id: sink.frame_ids.get(&s.topic).cloned().unwrap_or_default(),
        child_frame_id: sink
            .child_frame_ids
            .get(&s.topic)
            .cloned()
            .unwrap_or_default(),
        written: stamps.len(),
        first_last_ns: (
            stamps.first().copied().unwrap_or(0),
            stamps.last().copied().unwrap_or(0),
        ),
        cadence,
    })
}

fn finish_imu(
    s: &topics::Selected,
    sink: &Sink<'_>,
    options: &ConvertOptions,
    out: &Path,
    cadence: Cadence,
    w: &mut Vec<BagWarning>,
) -> Result<ImuNoiseYaml, BagError> {
    if cadence.rate_hz > 0.0 && cadence.rate_hz < LOW_IMU_RATE_HZ {
        w.push(BagWarning::LowRate {
            topic: s.topic.clone(),
            rate_hz: cadence.rate_hz,
            expected_min_hz: LOW_IMU_RATE_HZ,
        });
    }
    imu_unit_checks(&s.topic, sink, w);
    let stamps: Vec<u64> = sink.imu.iter().map(|(t, _)| *t).collect();
    let limit = FilterConfig::<f64>::new(ImuNoise::vn300()).max_imu_gap_ns;
    long_intervals(&s.topic, &stamps, limit, w);
    let noise = match &options.imu_noise {
        Some(noise) => noise.clone(),
        None => {
            let density = |var: f64| {
                (var > 0.0 && cadence.rate_hz > 0.0).then(|| (var / cadence.rate_hz).sqrt())
            };
            let (g, a) = sink.imu_covariance.unwrap_or_default();
            w.push(BagWarning::DefaultImuNoise {
                gyro_density_from_covariance: density(g[0]),
                accel_density_from_covariance: density(a[0]),
            });
            ImuNoiseYaml {
                update_rate: if cadence.rate_hz > 0.0 {
                    cadence.rate_hz
                } else {
                    DEFAULT_IMU_NOISE.update_rate
                },
                rostopic: Some(s.topic.clone()),
                ..DEFAULT_IMU_NOISE
            }
        }
    };
    noise.write(out.join(IMU_YAML))?;
    Ok(noise)
}

/// Units: |a| near g at the median, |w| below 35 rad/s.
fn imu_unit_checks(topic: &str, sink: &Sink<'_>, w: &mut Vec<BagWarning>) {
    let mut norms: Vec<f64> = sink.imu.iter().map(|(_, r)| r.accel.norm()).collect();
    norms.sort_by(f64::total_cmp);
    if let Some(&median_norm) = norms.get(norms.len() / 2) {
        if !(7.0..=12.5).contains(&median_norm) {
            w.push(BagWarning::AccelUnits {
                topic: topic.to_string(),
                median_norm,
            });
        }
    }
    let max_abs = sink
        .imu
        .iter()
        .map(|(_, r)| r.gyro.amax())
        .fold(0.0, f64::max);
    if max_abs > 35.0 {
        w.push(BagWarning::GyroUnits {
            topic: topic.to_string(),
            max_abs,
        });
    }
}

fn finish_pose(
    options: &ConvertOptions,
    out: &Path,
    cadence: Cadence,
    w: &mut Vec<BagWarning>,
) -> Result<(), BagError> {
    let sensor = options.pose_noise.clone().unwrap_or_else(|| {
        w.push(BagWarning::DefaultPoseNoise);
        PoseSensorYaml {
            rate_hz: (cadence.rate_hz > 0.0).then_some(cadence.rate_hz),
            ..DEFAULT_POSE_NOISE
        }
    });
    sensor.write(out.join(POSE_SENSOR_YAML))?;
    Ok(())
}

fn finish_lidar(
    s: &topics::Selected,
    sink: &Sink<'_>,
    out: &Path,
    cadence: Cadence,
    w: &mut Vec<BagWarning>,
) -> Result<Option<PointTime>, BagError> {
    let track = &sink.lidar;
    let topic = s.topic.clone();
    match &track.time {
        Some(PointTime::Missing) | None => w.push(BagWarning::MissingPointTime {
            topic,
            fields: track.fields.clone(),
        }),
        Some(PointTime::Field { .. }) if track.span_dropped > 0 => {
            w.push(BagWarning::PointTimeSpan {
                topic,
                scans: track.span_dropped,
                largest_s: track.largest_span_ns as f64 * 1e-9,
            });
        }
        Some(PointTime::Field { .. }) if !track.any_time => {
            w.push(BagWarning::PointTimeConstant { topic });
        }
        Some(PointTime::Field { .. }) => {}
    }
    LidarYaml {
        rings: track.max_ring.map(|r| u32::from(r) + 1),
        columns: None,
        scan_rate_hz: (cadence.rate_hz > 0.0).then_some(cadence.rate_hz),
        range_noise_m: None,
    }
    .write(out.join(LIDAR_YAML))?;
    Ok(track.time.clone())
}

fn finish_camera(
    options: &ConvertOptions,
    out: &Path,
    w: &mut Vec<BagWarning>,
) -> Result<(), BagError> {
    for (given, file) in [
        (&options.camera_yaml, CAMERA_YAML),
        (&options.target_yaml, TARGET_YAML),
    ] {
        match given {
            Some(source) => {
                std::fs::copy(source, out.join(file)).map_err(|e| BagError::Io {
                    path: source.clone(),
                    source: e,
                })?;
            }
            None => w.push(BagWarning::MissingCameraFile { file }),
        }
    }
    Ok(())
}

fn write_dataset_yaml(path: &Path, out: &Path, summary: &ConvertSummary) -> Result<(), BagError> {
    let sensors = summary.streams.iter().map(|s| s.role.sensor().to_string());
    let rates_hz: BTreeMap<String, f64> = summary
        .streams
        .iter()
        .map(|s| (s.role.sensor().to_string(), s.cadence.rate_hz))
        .collect();
    let topics: Vec<String> = summary
        .streams
        .iter()
        .map(|s| {
            let child = if s.child_frame_id.is_empty() {
                String::new()
            } else {
                format!(", child_frame_id `{}`", s.child_frame_id)
            };
            format!(
                "{} <- {} ({}, frame_id `{}`{child})",
                s.role.sensor(),
                s.topic,
                s.msg_type,
                s.frame_id
            )
        })
        .collect();
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    DatasetYaml {
        sensors: sensors.collect(),
        description: format!(
            "msreg convert from {:?} file {}: {}",
            summary.format,
            name.unwrap_or_default(),
            topics.join("; ")
        ),
        rates_hz,
    }
    .write(out.join(DATASET_YAML))?;
    Ok(())
}
