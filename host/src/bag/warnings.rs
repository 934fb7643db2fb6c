//! Load-time sanity checks: what a conversion noticed but did not refuse. Each is a typed
//! [`BagWarning`] in the [`super::ConvertSummary`]; the CLI prints them.

use std::fmt;

/// Something suspicious in the bag (the conversion went on).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[non_exhaustive]
pub enum BagWarning {
    /// Several topics fit a role and none was named: the role was skipped.
    AmbiguousTopic {
        /// `imu`, `lidar`, `camera`, `pose`.
        role: &'static str,
        /// The topics of an accepted type.
        candidates: Vec<String>,
    },
    /// No `--imu-config`: the documented default noise figures were written.
    DefaultImuNoise {
        /// Gyro noise density implied by the messages' covariance, rad/s/sqrt(Hz)
        /// (`sqrt(var / rate)`), when the covariance is filled.
        gyro_density_from_covariance: Option<f64>,
        /// Accelerometer noise density implied likewise, m/s^2/sqrt(Hz).
        accel_density_from_covariance: Option<f64>,
    },
    /// No `--pose-config`: the documented default increment noise was written.
    DefaultPoseNoise,
    /// No `--camera-config` / `--target`: `cam0/camera.yaml` or `target.yaml` is missing.
    MissingCameraFile {
        /// The file not written.
        file: &'static str,
    },
    /// A sensor's rate is lower than its use needs.
    LowRate {
        /// Topic.
        topic: String,
        /// Median rate, Hz.
        rate_hz: f64,
        /// Least rate the pipelines are meant for, Hz.
        expected_min_hz: f64,
    },
    /// Intervals well above the median (> 3x).
    Gaps {
        /// Topic.
        topic: String,
        /// Gaps found.
        count: usize,
        /// Longest gap, s.
        largest_s: f64,
        /// Where the longest starts, s after the first stamp.
        at_s: f64,
        /// Median interval, s.
        median_dt_s: f64,
    },
    /// IMU intervals longer than the filter accepts: the calibration will refuse the data
    /// (exit code 2) until the recording is cut there.
    ImuGapOverFilterLimit {
        /// Topic.
        topic: String,
        /// Intervals over the limit.
        count: usize,
        /// Longest, s.
        largest_s: f64,
        /// Where the longest starts, s after the first stamp.
        at_s: f64,
        /// The filter's limit (`FilterConfig::max_imu_gap_ns`), s.
        limit_s: f64,
    },
    /// Header stamps that go backwards in recording order (sorted before writing).
    TimestampJumps {
        /// Topic.
        topic: String,
        /// Backward steps.
        count: usize,
        /// Largest backward step, s.
        largest_s: f64,
    },
    /// Messages with the same header stamp as an earlier one (dropped).
    DuplicateStamps {
        /// Topic.
        topic: String,
        /// Dropped messages.
        count: usize,
    },
    /// Header stamps of zero: the bag's receive time was used instead.
    ZeroStamps {
        /// Topic.
        topic: String,
        /// Messages concerned.
        count: usize,
    },
    /// The header `frame_id` changes within the topic.
    FrameIdChanged {
        /// Topic.
        topic: String,
        /// First frame id.
        first: String,
        /// A later, different one.
        other: String,
    },
    /// The accelerometer magnitude is far from g (units in g? gravity removed?).
    AccelUnits {
        /// Topic.
        topic: String,
        /// Median |a|, in the message's units.
        median_norm: f64,
    },
    /// Angular rates above 35 rad/s (deg/s instead of rad/s?).
    GyroUnits {
        /// Topic.
        topic: String,
        /// Largest |w|.
        max_abs: f64,
    },
    /// An IMU message marks its gyro or accelerometer as absent (covariance[0] = -1).
    ImuChannelAbsent {
        /// Topic.
        topic: String,
        /// `angular_velocity` or `linear_acceleration`.
        field: &'static str,
    },
    /// Point clouds without a per-point time field: `t = 0` everywhere, no deskewing.
    MissingPointTime {
        /// Topic.
        topic: String,
        /// Field names present.
        fields: Vec<String>,
    },
    /// Per-point times spanning more than 1 s within a scan: the unit or the absolute /
    /// relative guess is wrong; those scans' times were set to zero.
    PointTimeSpan {
        /// Topic.
        topic: String,
        /// Scans concerned.
        scans: usize,
        /// Largest span, s.
        largest_s: f64,
    },
    /// Per-point times all equal in every scan (a time field that carries nothing).
    PointTimeConstant {
        /// Topic.
        topic: String,
    },
    /// Poses with a quaternion far from unit norm (zero, uninitialised): skipped.
    BadQuaternions {
        /// Topic.
        topic: String,
        /// Messages skipped.
        count: usize,
    },
}

impl fmt::Display for BagWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use BagWarning as W;
        match self {
            W::AmbiguousTopic { role, candidates } => write!(
                f,
                "{} topics fit --{role} ({}): none converted, name one with --{role}",
                candidates.len(),
                candidates.join(", ")
            ),
            W::DefaultImuNoise {
                gyro_density_from_covariance: g,
                accel_density_from_covariance: a,
            } => {
                write!(
                    f,
                    "a bag carries no IMU noise figures: imu0/imu.yaml has the documented \
                     defaults (docs/bags.md); pass --imu-config imu.yaml (Kalibr keys)"
                )?;
                if let (Some(g), Some(a)) = (g, a) {
                    write!(
                        f,
                        "; the messages' covariance implies gyroscope_noise_density {g:.3e}, \
                         accelerometer_noise_density {a:.3e}"
                    )?;
                }
                Ok(())
            }
            W::DefaultPoseNoise => write!(
                f,
                "no pose noise given: pose0/sensor.yaml has the documented defaults \
                 (docs/bags.md); pass --pose-config sensor.yaml"
            ),
            W::MissingCameraFile { file } => write!(
                f,
                "{file} not written (pass --camera-config / --target); camera calibration needs it"
            ),
            _ => self.fmt_stream(f),
        }
    }
}

impl BagWarning {
    /// Display of the stream-timing warnings.
    fn fmt_stream(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use BagWarning as W;
        match self {
            W::LowRate {
                topic,
                rate_hz,
                expected_min_hz,
            } => write!(
                f,
                "{topic}: {rate_hz:.1} Hz is below the {expected_min_hz} Hz the pipelines are meant for"
            ),
            W::Gaps {
                topic,
                count,
                largest_s,
                at_s,
                median_dt_s,
            } => write!(
                f,
                "{topic}: {count} gap(s) over 3x the median interval {:.1} ms; longest {:.1} ms at {at_s:.3} s",
                median_dt_s * 1e3,
                largest_s * 1e3
            ),
            W::ImuGapOverFilterLimit {
                topic,
                count,
                largest_s,
                at_s,
                limit_s,
            } => write!(
                f,
                "{topic}: {count} interval(s) over the filter's {:.0} ms limit, longest {:.1} ms \
                 at {at_s:.3} s: the calibration will refuse the data there",
                limit_s * 1e3,
                largest_s * 1e3
            ),
            W::TimestampJumps {
                topic,
                count,
                largest_s,
            } => write!(
                f,
                "{topic}: header stamps go backwards {count} time(s), at most {:.3} ms (sorted)",
                largest_s * 1e3
            ),
            W::DuplicateStamps { topic, count } => {
                write!(f, "{topic}: {count} message(s) repeat an earlier stamp (dropped)")
            }
            W::ZeroStamps { topic, count } => write!(
                f,
                "{topic}: {count} message(s) with a zero header stamp: the bag's receive time used"
            ),
            W::FrameIdChanged {
                topic,
                first,
                other,
            } => write!(f, "{topic}: frame_id changes from `{first}` to `{other}`"),
            _ => self.fmt_content(f),
        }
    }

    /// Display of the message-content warnings.
    fn fmt_content(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use BagWarning as W;
        match self {
            W::AccelUnits { topic, median_norm } => write!(
                f,
                "{topic}: median |acceleration| {median_norm:.3}, far from 9.81 m/s^2 \
                 (in g? gravity removed?)"
            ),
            W::GyroUnits { topic, max_abs } => write!(
                f,
                "{topic}: angular rate up to {max_abs:.1}: deg/s instead of rad/s?"
            ),
            W::ImuChannelAbsent { topic, field } => write!(
                f,
                "{topic}: {field}_covariance[0] = -1 marks {field} as absent; its values are not measurements"
            ),
            W::MissingPointTime { topic, fields } => write!(
                f,
                "{topic}: no per-point time field (t, time, timestamp, offset_time) among [{}]: \
                 t = 0, scans cannot be deskewed",
                fields.join(", ")
            ),
            W::PointTimeSpan {
                topic,
                scans,
                largest_s,
            } => write!(
                f,
                "{topic}: per-point time spans up to {largest_s:.3} s in {scans} scan(s) \
                 (unit or absolute/relative wrong?): their times set to 0"
            ),
            W::PointTimeConstant { topic } => {
                write!(f, "{topic}: per-point time is constant within every scan")
            }
            W::BadQuaternions { topic, count } => write!(
                f,
                "{topic}: {count} pose(s) with a non-unit quaternion skipped"
            ),
            _ => Ok(()),
        }
    }
}

/// Statistics of one stream's stamps (sorted, unique).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Cadence {
    /// Median interval, s (0 with fewer than two stamps).
    pub median_dt_s: f64,
    /// 1 / median interval, Hz (0 with fewer than two stamps).
    pub rate_hz: f64,
}

/// Median interval and gap warning of sorted, unique `stamps`.
pub fn cadence(topic: &str, stamps: &[u64], warnings: &mut Vec<BagWarning>) -> Cadence {
    let mut dts: Vec<u64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    if dts.is_empty() {
        return Cadence::default();
    }
    let gaps_at: Vec<(usize, u64)> = dts.iter().copied().enumerate().collect();
    dts.sort_unstable();
    let median = dts[dts.len() / 2];
    let median_dt_s = median as f64 * 1e-9;
    let gaps: Vec<&(usize, u64)> = gaps_at.iter().filter(|(_, dt)| *dt > 3 * median).collect();
    if let Some(&&(at, largest)) = gaps.iter().max_by_key(|(_, dt)| *dt) {
        warnings.push(BagWarning::Gaps {
            topic: topic.to_string(),
            count: gaps.len(),
            largest_s: largest as f64 * 1e-9,
            at_s: (stamps[at] - stamps[0]) as f64 * 1e-9,
            median_dt_s,
        });
    }
    Cadence {
        median_dt_s,
        rate_hz: if median > 0 { 1.0 / median_dt_s } else { 0.0 },
    }
}

/// Intervals of sorted `stamps` over `limit_ns`: one warning with their count and the
/// longest.
pub fn long_intervals(topic: &str, stamps: &[u64], limit_ns: u64, warnings: &mut Vec<BagWarning>) {
    let over: Vec<(usize, u64)> = stamps
        .windows(2)
        .map(|w| w[1] - w[0])
        .enumerate()
        .filter(|(_, dt)| *dt > limit_ns)
        .collect();
    if let Some(&(at, largest)) = over.iter().max_by_key(|(_, dt)| *dt) {
        warnings.push(BagWarning::ImuGapOverFilterLimit {
            topic: topic.to_string(),
            count: over.len(),
            largest_s: largest as f64 * 1e-9,
            at_s: (stamps[at] - stamps[0]) as f64 * 1e-9,
            limit_s: limit_ns as f64 * 1e-9,
        });
    }
}

/// Sorts `items` by stamp and drops repeated stamps, warning about backward jumps (in
/// recording order) and duplicates.
pub fn sort_stamped<T>(topic: &str, items: &mut Vec<(u64, T)>, warnings: &mut Vec<BagWarning>) {
    let backwards: Vec<u64> = items
        .windows(2)
        .filter(|w| w[1].0 < w[0].0)
        .map(|w| w[0].0 - w[1].0)
        .collect();
    if let Some(&largest) = backwards.iter().max() {
        warnings.push(BagWarning::TimestampJumps {
            topic: topic.to_string(),
            count: backwards.len(),
            largest_s: largest as f64 * 1e-9,
        });
    }
    items.sort_by_key(|(stamp, _)| *stamp);
    let before = items.len();
    items.dedup_by_key(|(stamp, _)| *stamp);
    if items.len() < before {
        warnings.push(BagWarning::DuplicateStamps {
            topic: topic.to_string(),
            count: before - items.len(),
        });
    }
}
