//! Typed errors of the estimator. Every error leaves the filter state untouched.

use core::fmt;

/// Why the filter refused an input. The state is unchanged whenever one is returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// A value was NaN or infinite.
    NonFinite,
    /// A value was finite but physically implausible (e.g. a 10^6 rad/s gyro reading).
    OutOfRange,
    /// A timestamp is earlier than the filter's current time.
    TimeWentBackwards {
        /// The filter time, ns.
        filter_ns: u64,
        /// The offending stamp, ns.
        stamp_ns: u64,
    },
    /// The measurement's IMU time lies beyond the newest IMU sample: feed IMU samples until
    /// one is at or after it (see `Ekf::is_due`).
    NotYetDue {
        /// The measurement's IMU time, ns.
        imu_time_ns: u64,
        /// The newest IMU stamp, ns.
        horizon_ns: u64,
    },
    /// Two consecutive IMU samples are further apart than `FilterConfig::max_imu_gap_ns`.
    ImuGap {
        /// Length of the gap, ns.
        gap_ns: u64,
    },
    /// No IMU sample has been received yet, so the filter cannot propagate.
    NotInitialized,
    /// The sensor index is not part of this filter's layout.
    UnknownSensor,
    /// The measurement refers to a clone that has left the window (or never existed).
    OlderThanWindow,
    /// A relative measurement's start does not match the sensor's anchor clone.
    NoAnchor,
    /// The clone window is full of anchors of other sensors.
    CloneWindowFull,
    /// The innovation covariance is not positive definite.
    SingularInnovation,
    /// The computed correction was not finite; the update was discarded.
    DivergentUpdate,
    /// A configuration or prior value is invalid (non-positive sigma, ...).
    InvalidConfig,
    /// The static-frame index is not part of this filter's layout.
    UnknownFrame,
    /// The measurement refers to a static frame that has not been initialised.
    FrameNotInitialized,
    /// A target point could not be projected into the camera at the current estimate
    /// (behind it or outside the model's domain).
    NotProjectable,
    /// The measurement holds no observations.
    EmptyMeasurement,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::NonFinite => write!(f, "input contains NaN or infinity"),
            Error::OutOfRange => write!(f, "input value out of the plausible range"),
            Error::TimeWentBackwards {
                filter_ns,
                stamp_ns,
            } => write!(
                f,
                "time went backwards: stamp {stamp_ns} ns is before filter time {filter_ns} ns"
            ),
            Error::NotYetDue {
                imu_time_ns,
                horizon_ns,
            } => write!(
                f,
                "not yet due: IMU time {imu_time_ns} ns is after the newest IMU sample {horizon_ns} ns"
            ),
            Error::ImuGap { gap_ns } => write!(f, "gap of {gap_ns} ns in the IMU stream"),
            Error::NotInitialized => write!(f, "no IMU sample received yet"),
            Error::UnknownSensor => write!(f, "sensor index not in the filter layout"),
            Error::OlderThanWindow => write!(f, "measurement older than the clone window"),
            Error::NoAnchor => write!(f, "relative measurement without a matching anchor"),
            Error::CloneWindowFull => write!(f, "clone window full"),
            Error::SingularInnovation => write!(f, "innovation covariance not positive definite"),
            Error::DivergentUpdate => write!(f, "update produced a non-finite correction"),
            Error::InvalidConfig => write!(f, "invalid configuration or prior"),
            Error::UnknownFrame => write!(f, "static frame index not in the filter layout"),
            Error::FrameNotInitialized => write!(f, "static frame not initialised"),
            Error::NotProjectable => write!(f, "target point not projectable at the estimate"),
            Error::EmptyMeasurement => write!(f, "measurement without observations"),
        }
    }
}
