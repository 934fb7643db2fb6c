//! The conversion proper: decodes each message of a chosen topic and turns it into the
//! dataset layout (docs/formats.md), with the project's writers: PCD scans and PNG images
//! as they arrive, the IMU and pose CSVs (sorted, checked) at the end.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion};

use super::cloud::{convert_cloud, PointTime, MAX_SPAN_NS};
use super::error::{BagError, DecodeError};
use super::image::{convert_compressed, convert_image, ImageOut};
use super::msgs::{CompressedImageMsg, ImageMsg, ImuMsg, PointCloud2Msg, StampedPose};
use super::topics::{Role, Selected};
use super::warnings::BagWarning;
use super::wire::{Header, WireReader};
use crate::dataset::{CameraFrame, ImuRecord, PoseRecord, CAMERA_DATA_DIR, LIDAR_DIR};
use crate::pointcloud::{write_pcd, PcdWriteOptions};

/// A quaternion this far from unit norm is not a rotation (0 = uninitialised).
const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// What the per-point time of the LiDAR topic looked like over all scans.
#[derive(Debug, Clone, Default)]
pub(crate) struct LidarTrack {
    /// Time interpretation of the first scan with points.
    pub time: Option<PointTime>,
    /// Field names of the first message.
    pub fields: Vec<String>,
    /// Scans whose time span exceeded 1 s.
    pub span_dropped: usize,
    /// Largest span, ns.
    pub largest_span_ns: u64,
    /// Some scan had a non-zero time offset.
    pub any_time: bool,
    /// Highest ring index seen (when a ring field exists).
    pub max_ring: Option<u16>,
}

/// The state of one conversion.
pub(crate) struct Sink<'p> {
    path: &'p Path,
    out: PathBuf,
    by_topic: BTreeMap<String, Selected>,
    /// Messages seen per topic (for error messages).
    seen: BTreeMap<String, usize>,
    /// First frame id per topic.
    pub frame_ids: BTreeMap<String, String>,
    frame_changed: BTreeSet<String>,
    /// Odometry's `child_frame_id` (the moving frame) per topic, first message.
    pub child_frame_ids: BTreeMap<String, String>,
    zero_stamps: BTreeMap<String, usize>,
    pub imu: Vec<(u64, ImuRecord)>,
    /// Covariance diagonals of the first IMU message: gyro, accel.
    pub imu_covariance: Option<([f64; 3], [f64; 3])>,
    imu_absent: BTreeSet<&'static str>,
    pub poses: Vec<(u64, PoseRecord)>,
    bad_quaternions: usize,
    pub scans: Vec<(u64, ())>,
    pub lidar: LidarTrack,
    pub images: Vec<(u64, CameraFrame)>,
    written: BTreeSet<(Role, u64)>,
    duplicates: BTreeMap<Role, usize>,
    pub warnings: Vec<BagWarning>,
}

impl<'p> Sink<'p> {
    /// A sink writing under `out` the topics `selected`.
    pub fn new(path: &'p Path, out: &Path, selected: &[Selected]) -> Self {
        Self {
            path,
            out: out.to_path_buf(),
            by_topic: selected
                .iter()
                .map(|s| (s.topic.clone(), s.clone()))
                .collect(),
            seen: BTreeMap::new(),
            frame_ids: BTreeMap::new(),
            frame_changed: BTreeSet::new(),
            child_frame_ids: BTreeMap::new(),
            zero_stamps: BTreeMap::new(),
            imu: Vec::new(),
            imu_covariance: None,
            imu_absent: BTreeSet::new(),
            poses: Vec::new(),
            bad_quaternions: 0,
            scans: Vec::new(),
            lidar: LidarTrack::default(),
            images: Vec::new(),
            written: BTreeSet::new(),
            duplicates: BTreeMap::new(),
            warnings: Vec::new(),
        }
    }

    /// Decodes and stores one message.
    pub fn accept(&mut self, topic: &str, log_time_ns: u64, data: &[u8]) -> Result<(), BagError> {
        let Some(selected) = self.by_topic.get(topic).cloned() else {
            return Ok(());
        };
        let index = *self
            .seen
            .entry(topic.to_string())
            .and_modify(|n| *n += 1)
            .or_insert(0);
        let decode_error = decode_error(self.path, topic, index);
        let mut r = WireReader::new(data, selected.dialect).map_err(decode_error)?;
        let result = match selected.role {
            Role::Imu => ImuMsg::decode(&mut r).map(|m| self.imu_message(topic, log_time_ns, m)),
            Role::Pose => self.pose_message(&selected, &mut r, log_time_ns),
            Role::Lidar => return self.cloud_message(topic, &mut r, log_time_ns, index),
            Role::Camera => return self.image_message(&selected, &mut r, log_time_ns, index),
        };
        result.map_err(decode_error)
    }

    /// The header stamp, or the receive time when the header stamp is unset; tracks the
    /// frame id.
    fn stamp(&mut self, topic: &str, header: &Header, log_time_ns: u64) -> u64 {
        match self.frame_ids.get(topic) {
            None => {
                self.frame_ids
                    .insert(topic.to_string(), header.frame_id.clone());
            }
            Some(first) if *first != header.frame_id && self.frame_changed.insert(topic.into()) => {
                self.warnings.push(BagWarning::FrameIdChanged {
                    topic: topic.to_string(),
                    first: first.clone(),
                    other: header.frame_id.clone(),
                });
            }
            Some(_) => {}
        }
        if header.stamp_ns == 0 {
            *self.zero_stamps.entry(topic.to_string()).or_default() += 1;
            log_time_ns
        } else {
            header.stamp_ns
        }
    }

    fn imu_message(&mut self, topic: &str, log_time_ns: u64, m: ImuMsg) {
        let stamp_ns = self.stamp(topic, &m.header, log_time_ns);
        let diag = |c: &[f64; 9]| [c[0], c[4], c[8]];
        if self.imu_covariance.is_none() {
            self.imu_covariance = Some((
                diag(&m.angular_velocity_covariance),
                diag(&m.linear_acceleration_covariance),
            ));
        }
        for (cov, field) in [
            (&m.angular_velocity_covariance, "angular_velocity"),
            (&m.linear_acceleration_covariance, "linear_acceleration"),
        ] {
            if cov[0] < 0.0 && self.imu_absent.insert(field) {
                self.warnings.push(BagWarning::ImuChannelAbsent {
                    topic: topic.to_string(),
                    field,
                });
            }
        }
        self.imu.push((
            stamp_ns,
            ImuRecord {
                stamp_ns,
                gyro: m.angular_velocity,
                accel: m.linear_acceleration,
            },
        ));
    }

    fn pose_message(
        &mut self,
        selected: &Selected,
        r: &mut WireReader<'_>,
        log_time_ns: u64,
    ) -> Result<(), DecodeError> {
        let m = if selected.msg_type == "nav_msgs/Odometry" {
            StampedPose::decode_odometry(r)?
        } else {
            StampedPose::decode_pose_stamped(r)?
        };
        let stamp_ns = self.stamp(&selected.topic, &m.header, log_time_ns);
        if !m.child_frame_id.is_empty() {
            self.child_frame_ids
                .entry(selected.topic.clone())
                .or_insert(m.child_frame_id);
        }
        let Some(rotation) = unit_rotation(m.pose.orientation) else {
            self.bad_quaternions += 1;
            return Ok(());
        };
        self.poses.push((
            stamp_ns,
            PoseRecord {
                stamp_ns,
                position: m.pose.position,
                rotation,
            },
        ));
        Ok(())
    }

    fn cloud_message(
        &mut self,
        topic: &str,
        r: &mut WireReader<'_>,
        log_time_ns: u64,
        index: usize,
    ) -> Result<(), BagError> {
        let decode_error = decode_error(self.path, topic, index);
        let msg = PointCloud2Msg::decode(r).map_err(decode_error)?;
        let header_stamp = self.stamp(topic, &msg.header, log_time_ns);
        let scan = convert_cloud(&msg, header_stamp).map_err(decode_error)?;
        let track = &mut self.lidar;
        if track.fields.is_empty() {
            track.fields = msg.fields.iter().map(|f| f.name.clone()).collect();
        }
        if track.time.is_none() && !scan.cloud.points.is_empty() {
            track.time = Some(scan.time.clone());
        }
        if scan.time_dropped {
            track.span_dropped += 1;
        }
        track.largest_span_ns = track.largest_span_ns.max(scan.span_ns);
        track.any_time |= scan.span_ns > 0 && scan.span_ns <= MAX_SPAN_NS;
        if msg
            .fields
            .iter()
            .any(|f| ["ring", "line", "channel"].contains(&f.name.as_str()))
        {
            let ring = scan.cloud.points.iter().map(|p| p.ring).max();
            track.max_ring = track.max_ring.max(ring);
        }
        self.scans.push((scan.stamp_ns, ()));
        if !self.first_write(Role::Lidar, scan.stamp_ns) {
            return Ok(());
        }
        let file = self
            .out
            .join(LIDAR_DIR)
            .join(format!("{}.pcd", scan.stamp_ns));
        let options = PcdWriteOptions {
            xyz_f64: scan.xyz_f64,
            ..PcdWriteOptions::default()
        };
        write_pcd(&file, &scan.cloud, options)?;
        Ok(())
    }

    fn image_message(
        &mut self,
        selected: &Selected,
        r: &mut WireReader<'_>,
        log_time_ns: u64,
        index: usize,
    ) -> Result<(), BagError> {
        let decode_error = decode_error(self.path, &selected.topic, index);
        let (header, out) = if selected.msg_type == "sensor_msgs/Image" {
            let m = ImageMsg::decode(r).map_err(decode_error)?;
            (m.header.clone(), convert_image(&m).map_err(decode_error)?)
        } else {
            let m = CompressedImageMsg::decode(r).map_err(decode_error)?;
            (
                m.header.clone(),
                convert_compressed(&m).map_err(decode_error)?,
            )
        };
        let stamp_ns = self.stamp(&selected.topic, &header, log_time_ns);
        if !self.first_write(Role::Camera, stamp_ns) {
            return Ok(());
        }
        let file = self
            .out
            .join(CAMERA_DATA_DIR)
            .join(format!("{stamp_ns}.png"));
        match out {
            ImageOut::Pixels(image) => image
                .save_with_format(&file, image::ImageFormat::Png)
                .map_err(|source| BagError::Image {
                    path: file.clone(),
                    source,
                })?,
            ImageOut::PngBytes(bytes) => {
                std::fs::write(&file, bytes).map_err(|source| BagError::Io {
                    path: file.clone(),
                    source,
                })?;
            }
        }
        self.images.push((
            stamp_ns,
            CameraFrame {
                stamp_ns,
                path: file,
            },
        ));
        Ok(())
    }

    /// True the first time a file of `role` with this stamp is to be written.
    fn first_write(&mut self, role: Role, stamp_ns: u64) -> bool {
        let first = self.written.insert((role, stamp_ns));
        if !first {
            *self.duplicates.entry(role).or_default() += 1;
        }
        first
    }

    /// The warnings that are counts over the whole bag.
    pub fn count_warnings(&mut self) {
        for (topic, &count) in &self.zero_stamps {
            self.warnings.push(BagWarning::ZeroStamps {
                topic: topic.clone(),
                count,
            });
        }
        let topic_of = |role: Role| {
            self.by_topic
                .values()
                .find(|s| s.role == role)
                .map(|s| s.topic.clone())
                .unwrap_or_default()
        };
        for (&role, &count) in &self.duplicates {
            self.warnings.push(BagWarning::DuplicateStamps {
                topic: topic_of(role),
                count,
            });
        }
        if self.bad_quaternions > 0 {
            self.warnings.push(BagWarning::BadQuaternions {
                topic: topic_of(Role::Pose),
                count: self.bad_quaternions,
            });
        }
    }
}

/// The error of message `index` of `topic`.
fn decode_error<'a>(
    path: &'a Path,
    topic: &'a str,
    index: usize,
) -> impl Fn(DecodeError) -> BagError + Copy + 'a {
    move |source| BagError::Decode {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        index,
        source,
    }
}

/// A rotation from a stored quaternion, `None` when it is far from unit norm.
fn unit_rotation(q: Quaternion<f64>) -> Option<UnitQuaternion<f64>> {
    let norm = q.norm();
    if !norm.is_finite() || (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return None;
    }
    Some(if (norm - 1.0).abs() <= 1e-12 {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::new_normalize(q)
    })
}
