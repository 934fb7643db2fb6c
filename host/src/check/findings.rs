//! The typed findings of `msreg check`, their severity and their message.

use std::fmt;
use std::path::PathBuf;

/// How bad a finding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// The calibration cannot succeed, or would be wrong: stop.
    Error,
    /// Worth fixing; the calibration may still work.
    Warning,
    /// A measured fact (rates, offsets, excitation).
    Note,
}

/// A stamp span, s (the stamps' own epoch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// First stamp, s.
    pub start_s: f64,
    /// Last stamp, s.
    pub end_s: f64,
}

impl Span {
    /// Length, s.
    pub fn duration_s(&self) -> f64 {
        self.end_s - self.start_s
    }
}

impl fmt::Display for Span {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:.3} to {:.3} s ({:.1} s)",
            self.start_s,
            self.end_s,
            self.duration_s()
        )
    }
}

/// One thing `msreg check` found.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Finding {
    /// The dataset directory does not exist.
    NoDirectory {
        /// The path given.
        path: PathBuf,
    },
    /// Files the pipeline needs are missing (all of them, at once).
    MissingFiles {
        /// The pipeline.
        pipeline: &'static str,
        /// Each missing file, or alternatives joined by " or ".
        files: Vec<String>,
    },
    /// No sensor data at all.
    NoSensorData {
        /// The files looked for.
        looked_for: Vec<String>,
    },
    /// A file is present but cannot be read (its own error names file and line).
    Unreadable {
        /// The reader's message.
        message: String,
    },
    /// A YAML key no reader knows (it is ignored).
    UnknownKey {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The key.
        key: String,
        /// The known key it is closest to.
        suggestion: Option<&'static str>,
    },
    /// A stream's span, rate and sample count.
    Rate {
        /// `imu0`, `cam0`, ...
        stream: String,
        /// Samples.
        samples: usize,
        /// Its span.
        span: Span,
        /// Median rate, Hz.
        rate_hz: f64,
    },
    /// Intervals much longer than the median one.
    Gaps {
        /// The stream.
        stream: String,
        /// How many.
        count: usize,
        /// The longest, s.
        longest_s: f64,
        /// Where it starts, s after the stream's first stamp.
        at_s: f64,
        /// The median interval, s.
        nominal_s: f64,
    },
    /// A stream shares no time with the IMU.
    NoOverlap {
        /// The stream.
        stream: String,
        /// The IMU's span.
        imu: Span,
        /// The stream's span.
        other: Span,
    },
    /// A stream shares only part of its time with the IMU.
    PartialOverlap {
        /// The stream.
        stream: String,
        /// Shared time, s.
        overlap_s: f64,
        /// The stream's length, s.
        duration_s: f64,
    },
    /// IMU units (the loader's message: accelerometer in g, gyro in deg/s).
    ImuUnits {
        /// The loader's message, naming the file.
        message: String,
    },
    /// A target size that reads as millimetres.
    TargetInMillimetres {
        /// `target.yaml`.
        path: PathBuf,
        /// 1-based line of the key.
        line: usize,
        /// The key.
        key: &'static str,
        /// Its value.
        value: f64,
    },
    /// How often the target was found in the images.
    TargetFound {
        /// "6x7 checkerboard".
        target: String,
        /// Images with the target.
        found: usize,
        /// Images.
        images: usize,
        /// Rejections per reason.
        rejected: Vec<(String, usize)>,
    },
    /// A sensor's clock offset from the cross-correlation of angular rates.
    TimeOffset {
        /// The sensor.
        stream: String,
        /// `t_d`, s (sensor stamp + t_d = IMU time).
        offset_s: f64,
        /// Peak correlation.
        correlation: f64,
        /// Correlation at zero offset.
        correlation_at_zero: f64,
        /// Increments correlated.
        increments: usize,
    },
    /// The offset search found no clear peak.
    TimeOffsetUnclear {
        /// The sensor.
        stream: String,
        /// Best correlation found.
        correlation: f64,
    },
    /// Rotation per IMU axis over the shared time.
    Excitation {
        /// Angle turned about x, y, z (integral of |w_i|), deg.
        angle_deg: [f64; 3],
        /// RMS rate per axis, deg/s.
        rms_deg_s: [f64; 3],
        /// Second over first eigenvalue of the rate scatter.
        second_axis_ratio: f64,
        /// Whether this is too little (a warning).
        low: bool,
    },
    /// The camera's PnP motion against the accelerometer's: the target's scale.
    Scale {
        /// PnP translation / IMU translation.
        ratio: f64,
        /// Its standard error (from the fit's residuals).
        sigma: f64,
        /// `target.yaml`'s square (or tag) size, m.
        size_m: f64,
        /// The key it comes from.
        key: &'static str,
        /// Whether the corners' positions come from the x, y, z of `cam0/corners.csv`.
        from_corners_csv: bool,
        /// Gravity magnitude the fit found, m/s^2 (9.81 when the fit is sound).
        gravity: f64,
        /// Frames used.
        frames: usize,
    },
    /// The scale fit could not decide.
    ScaleUnclear {
        /// Why.
        reason: String,
    },
}

/// Largest time offset accepted without re-stamping, s: twice the 50 ms prior sigma
/// (docs/recording.md, "One clock, or nearly").
pub const MAX_TIME_OFFSET_S: f64 = 0.1;
/// Offsets above this are worth a warning, s (the prior's sigma).
pub const WARN_TIME_OFFSET_S: f64 = 0.05;
/// Scale ratio beyond `1 +- this` is an error. Measured on good data: within 0.001 of 1 on
/// simulated seeds 1-5 (8 s, with and without blur and noise), 1.008 +- 0.004 on EuRoC's
/// imu_april (real); a 7 cm square given for a 6 cm board reads 1.167.
pub const MAX_SCALE_ERROR: f64 = 0.03;

impl Finding {
    /// How bad it is.
    pub fn severity(&self) -> Severity {
        match self {
            Self::NoDirectory { .. }
            | Self::MissingFiles { .. }
            | Self::NoSensorData { .. }
            | Self::Unreadable { .. }
            | Self::NoOverlap { .. }
            | Self::ImuUnits { .. }
            | Self::TargetInMillimetres { .. } => Severity::Error,
            Self::TargetFound { found, images, .. } if *found < 3 && *images > 0 => Severity::Error,
            Self::TargetFound { found, images, .. } if 2 * found < *images => Severity::Warning,
            Self::TimeOffset { offset_s, .. } if offset_s.abs() > MAX_TIME_OFFSET_S => {
                Severity::Error
            }
            Self::TimeOffset { offset_s, .. } if offset_s.abs() > WARN_TIME_OFFSET_S => {
                Severity::Warning
            }
            Self::Scale { ratio, .. } if (ratio - 1.0).abs() > MAX_SCALE_ERROR => Severity::Error,
            Self::UnknownKey { .. }
            | Self::Gaps { .. }
            | Self::PartialOverlap { .. }
            | Self::TimeOffsetUnclear { .. }
            | Self::ScaleUnclear { .. } => Severity::Warning,
            Self::Excitation { low: true, .. } => Severity::Warning,
            _ => Severity::Note,
        }
    }

    /// Whether the motion checks (offsets, excitation, scale) cannot run after it.
    pub fn blocks_motion(&self) -> bool {
        matches!(
            self,
            Self::NoDirectory { .. } | Self::ImuUnits { .. } | Self::TargetInMillimetres { .. }
        )
    }
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoDirectory { path } => write!(
                f,
                "{}: dataset directory does not exist or is not a directory",
                path.display()
            ),
            Self::MissingFiles { pipeline, files } => write!(
                f,
                "{pipeline} needs files that are missing: {}",
                files.join(", ")
            ),
            Self::NoSensorData { looked_for } => write!(
                f,
                "no sensor data found (looked for {}); docs/formats.md gives the layout",
                looked_for.join(", ")
            ),
            Self::Unreadable { message } => write!(f, "{message}"),
            Self::UnknownKey {
                path,
                line,
                key,
                suggestion,
            } => {
                write!(f, "{}:{line}: unknown key `{key}` ignored", path.display())?;
                match suggestion {
                    Some(s) => write!(f, " (did you mean `{s}`?)"),
                    None => Ok(()),
                }
            }
            Self::Rate {
                stream,
                samples,
                span,
                rate_hz,
            } => write!(f, "{stream}: {samples} samples at {rate_hz:.1} Hz, {span}"),
            Self::Gaps { .. } => fmt_gaps(self, f),
            Self::NoOverlap { stream, imu, other } => {
                let shift = other.start_s - imu.start_s;
                write!(
                    f,
                    "the streams do not overlap: imu0 spans {imu}, {stream} spans {other} \
                     ({stream} starts {shift:+.3} s from imu0); the clocks differ, re-stamp \
                     one of them"
                )
            }
            Self::PartialOverlap {
                stream,
                overlap_s,
                duration_s,
            } => write!(
                f,
                "{stream} shares only {overlap_s:.1} s of its {duration_s:.1} s with imu0"
            ),
            Self::ImuUnits { message } => write!(f, "{message}"),
            Self::TargetInMillimetres {
                path,
                line,
                key,
                value,
            } => write!(
                f,
                "{}:{line}: `{key}` is {value}, which as metres is a {value} m target: it \
                 looks like millimetres; write {} (metres)",
                path.display(),
                value * 1e-3
            ),
            Self::TargetFound { .. } => fmt_target_found(self, f),
            Self::TimeOffset { .. } => fmt_time_offset(self, f),
            Self::TimeOffsetUnclear {
                stream,
                correlation,
            } => write!(
                f,
                "{stream}: the angular rates do not correlate clearly with the gyro's (best \
                 {correlation:.2}); the time offset could not be checked"
            ),
            Self::Excitation { .. } => fmt_excitation(self, f),
            Self::Scale { .. } => fmt_scale(self, f),
            Self::ScaleUnclear { reason } => {
                write!(f, "the target's scale could not be checked: {reason}")
            }
        }
    }
}

fn fmt_time_offset(finding: &Finding, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    let Finding::TimeOffset {
        stream,
        offset_s,
        correlation,
        correlation_at_zero,
        increments,
    } = finding
    else {
        return Ok(());
    };
    write!(
        f,
        "{stream}: time offset ~{:.0} ms (stamp + offset = IMU time), from the \
         cross-correlation of its angular rate with the gyro's over {increments} increments \
         (peak {correlation:.3}, {correlation_at_zero:.3} at zero)",
        offset_s * 1e3
    )?;
    if offset_s.abs() > MAX_TIME_OFFSET_S {
        write!(
            f,
            ": beyond the prior range (0 +- 50 ms, at most {:.0} ms); shift the {stream} \
             stamps by {:+.0} ms (or the IMU's by {:+.0} ms) before calibrating",
            MAX_TIME_OFFSET_S * 1e3,
            offset_s * 1e3,
            -offset_s * 1e3
        )?;
    }
    Ok(())
}

fn fmt_excitation(finding: &Finding, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    let Finding::Excitation {
        angle_deg: a,
        rms_deg_s: r,
        second_axis_ratio,
        low,
    } = finding
    else {
        return Ok(());
    };
    write!(
        f,
        "excitation: imu0 turned {:.0} / {:.0} / {:.0} deg about x / y / z (rms rate {:.1} / \
         {:.1} / {:.1} deg/s); second / first axis of the rate scatter {second_axis_ratio:.3}",
        a[0], a[1], a[2], r[0], r[1], r[2]
    )?;
    if *low {
        write!(
            f,
            ": too little rotation about some axis (docs/recording.md asks for rotation about \
             all three axes, rms rate above {:.0} deg/s each, and a scatter ratio above 0.02)",
            super::motion::MIN_RMS_RATE_DEG_S
        )?;
    }
    Ok(())
}

fn fmt_scale(finding: &Finding, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    let Finding::Scale {
        ratio,
        sigma,
        size_m,
        key,
        from_corners_csv,
        gravity,
        frames,
    } = finding
    else {
        return Ok(());
    };
    write!(
        f,
        "target scale: the camera's translation from PnP is {ratio:.3} x the IMU's (+- \
         {sigma:.3}; fit of the accelerations over {frames} images, gravity {gravity:.2} m/s^2)"
    )?;
    if (ratio - 1.0).abs() > MAX_SCALE_ERROR && *from_corners_csv {
        write!(
            f,
            ": the x, y, z of cam0/corners.csv do not match the board; the motion says they \
             are {ratio:.3} times too large"
        )?;
    } else if (ratio - 1.0).abs() > MAX_SCALE_ERROR {
        write!(
            f,
            ": target.yaml's `{key}` {size_m} m does not match the board; the motion says \
             {:.4} m",
            size_m / ratio
        )?;
    }
    Ok(())
}

fn fmt_gaps(finding: &Finding, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    match finding {
        Finding::Gaps {
            stream,
            count,
            longest_s,
            at_s,
            nominal_s,
        } => write!(
            f,
            "{stream}: {count} gaps longer than 3 intervals of {:.1} ms; the longest is \
                 {:.1} ms, {at_s:.3} s after its first stamp",
            nominal_s * 1e3,
            longest_s * 1e3
        ),
        _ => Ok(()),
    }
}

fn fmt_target_found(finding: &Finding, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    match finding {
        Finding::TargetFound {
            target,
            found,
            images,
            rejected,
        } => {
            write!(
                f,
                "the {target} of target.yaml is found in {found} of {images} images"
            )?;
            if !rejected.is_empty() {
                let why: Vec<String> = rejected.iter().map(|(w, n)| format!("{n} x {w}")).collect();
                write!(f, " (rejected: {})", why.join(", "))?;
            }
            if *found < 3 && *images > 0 {
                write!(
                    f,
                    "; check that targetRows / targetCols count the inner corners and \
                         the target type"
                )?;
            }
            Ok(())
        }
        _ => Ok(()),
    }
}
