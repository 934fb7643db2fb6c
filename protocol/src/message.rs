//! The messages. Field order is wire order (postcard: integers as varints, `i32` zig-zag,
//! `f32` as 4 little-endian bytes, enums as a varint variant index). Units are in the field
//! names; stamps are `u64` ns of the sender's clock (docs/formats.md), poses follow
//! `T_a_b` = pose of `b` in `a`, quaternions are Hamilton `[w, x, y, z]`.

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::batch::Bounded;

/// IMU samples per [`ImuBatch`].
pub const IMU_BATCH_MAX: usize = 16;

/// Corners per [`CornerSet`]: a 6x7 or 6x8 checkerboard (Kalibr's example board and the
/// simulator's: 42) in one frame of at most 984 bytes (`HOST_FRAME_MAX`), under a quarter of
/// the device's 4 KiB receive ring. Larger targets (Kalibr's 6x6 aprilgrid: 144 corners) go
/// as several sets with the same stamp (docs/protocol.md).
pub const CORNER_SET_MAX: usize = 48;

/// Host to device.
// No heap on the device: a batch is stored inline, so the enum is as large as one batch.
#[allow(clippy::large_enum_variant)]
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub enum HostMsg {
    /// Handshake; the device answers with its own [`Hello`].
    Hello(Hello),
    /// (Re)starts the filter with this configuration.
    Config(Config),
    /// IMU samples, in stamp order.
    ImuBatch(ImuBatch),
    /// Start of an odometry segment of the pose sensor.
    Anchor(Anchor),
    /// An odometry increment of the pose sensor.
    RelativePose(RelativePose),
    /// Asks for a [`Status`].
    GetStatus,
    /// Initialises the target frame from the camera's pose of it in one image (camera-IMU).
    TargetPose(TargetPose),
    /// Target corners seen in one image (camera-IMU).
    CornerSet(CornerSet),
    /// Clock-sync request (v5): the device answers with a [`TimeSyncReply`] stamped on its
    /// own clock.
    TimeSync(TimeSyncRequest),
}

/// Device to host.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub enum DeviceMsg {
    /// Handshake answer (also sent once at boot).
    Hello(Hello),
    /// A host frame was received and handled.
    Ack(Ack),
    /// Extrinsic estimate, at the configured rate.
    Estimate(Estimate),
    /// One record per measurement update.
    UpdateDiagnostic(UpdateDiagnostic),
    /// The health monitor fired.
    HealthAlarm(HealthAlarm),
    /// Something was refused or lost; with the running count of its kind.
    ErrorReport(ErrorReport),
    /// Counters and state, on [`HostMsg::GetStatus`].
    Status(Status),
    /// Answer to [`HostMsg::TimeSync`] (v5), sent before its [`Ack`].
    TimeSync(TimeSyncReply),
}

/// Host half of a two-way clock-sync exchange (NTP-style): `t1` on the host clock.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeSyncRequest {
    /// Host clock just before the request is written, ns (echoed: it names the exchange).
    pub t1_ns: u64,
}

/// Which clock the device's filter runs on: the clock every measurement stamp must be on.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeBase {
    /// The IMU arrives over the link with the host's stamps (the QEMU link firmware): the
    /// filter runs on the host's data clock and the host sends stamps unmapped.
    HostStamps,
    /// The device stamps its own IMU (a board with the IMU driver): the host maps every
    /// measurement stamp onto the device clock with its clock-sync estimate.
    DeviceClock,
}

/// Device half of a clock-sync exchange: its clock when the request arrived and when this
/// reply left.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeSyncReply {
    /// The request's `t1_ns`, echoed.
    pub t1_ns: u64,
    /// Device clock when the request's first byte was received (UART RX interrupt), ns since
    /// boot.
    pub t2_ns: u64,
    /// Device clock just before this reply's first byte is written, ns since boot.
    pub t3_ns: u64,
    /// The clock the filter runs on.
    pub time_base: TimeBase,
}

/// Handshake: protocol version and frame limits of the sender.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hello {
    /// [`crate::VERSION`] of the sender.
    pub version: u16,
    /// Largest frame the sender accepts, bytes with delimiter.
    pub max_frame: u16,
    /// Receive buffer of the sender, bytes (the host keeps fewer unacknowledged bytes).
    pub rx_buffer: u16,
}

/// A pose `T_a_b`.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Default)]
pub struct Pose {
    /// `q_a_b`, Hamilton `[w, x, y, z]`.
    pub rotation_wxyz: [f32; 4],
    /// `p_a_b`, m.
    pub translation_m: [f32; 3],
}

/// IMU noise densities (Kalibr `imu.yaml`).
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct ImuNoise {
    /// rad/s/sqrt(Hz).
    pub gyro_noise_density: f32,
    /// m/s^2/sqrt(Hz).
    pub accel_noise_density: f32,
    /// rad/s^2/sqrt(Hz).
    pub gyro_random_walk: f32,
    /// m/s^3/sqrt(Hz).
    pub accel_random_walk: f32,
}

/// Confidence of a chi-square gate.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gate {
    /// 90 %.
    P90,
    /// 95 %.
    P95,
    /// 99 %.
    P99,
    /// 99.5 %.
    P995,
    /// 99.9 %.
    P999,
    /// 99.99 %.
    P9999,
    /// 99.999 %.
    P99999,
}

/// Which filter layout to run.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub enum SensorSet {
    /// IMU + one pose sensor (odometry) with extrinsic and time offset.
    PoseImu,
    /// IMU + one camera (extrinsic, time offset) and a static target seen in its images;
    /// the extrinsic of [`Config`] is `T_imu_cam`.
    CameraImu(CameraSetup),
    /// On-vehicle monitoring (`msreg monitor`): IMU + two pose sensors, `pose0` (e.g. LiDAR
    /// odometry; the prior of [`Config::sensor`]) and `pose1` (e.g. camera VO; the prior in
    /// the setup), each with extrinsic and time offset, in one filter (`MonitorEkf`).
    Monitor(MonitorSetup),
}

/// Prior of one sensor's calibration: initial `T_imu_sensor` and time offset with 1-sigmas.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct SensorPrior {
    /// Initial `T_imu_sensor`.
    pub extrinsic: Pose,
    /// Its rotation 1-sigma per axis, rad.
    pub sigma_rotation_rad: f32,
    /// Its translation 1-sigma per axis, m.
    pub sigma_translation_m: f32,
    /// Initial time offset `t_d`, s.
    pub time_offset_s: f32,
    /// Its 1-sigma, s (0 keeps it fixed).
    pub sigma_time_offset_s: f32,
}

/// The monitoring layout's second sensor, lever-arm hold and health-monitor tuning.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct MonitorSetup {
    /// Prior of `pose1` (sensor 1).
    pub pose1: SensorPrior,
    /// Planar motion: the lever arm of both sensors along this IMU-frame axis is held at its
    /// prior (`Ekf::hold_translation_axis`); `None`: nothing held.
    pub hold_translation_axis: Option<[f32; 3]>,
    /// Forgetting factor of the step detectors per update (`HealthConfig::step_forgetting`).
    pub step_forgetting: f32,
    /// `HealthConfig::resolvable_step_factor` (may be infinite: every direction tested).
    pub resolvable_step_factor: f32,
    /// Confidence of the step detectors' chi-square threshold per test
    /// (`HealthConfig::step_confidence`; docs/monitor.md, "False alarms").
    pub step_confidence: Gate,
}

/// Projection of a camera onto its normalised plane (Kalibr `camera_model`).
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub enum CameraProjection {
    /// `pinhole`.
    Pinhole,
    /// `omni` (Mei's unified model).
    Omni {
        /// Mirror parameter.
        xi: f32,
    },
}

/// Lens distortion (Kalibr `distortion_model`).
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub enum CameraDistortion {
    /// `none`.
    None,
    /// `radtan`: k1, k2, p1, p2, k3 (k3 zero for Kalibr's four coefficients).
    RadTan([f32; 5]),
    /// `equidistant`: k1, k2, k3, k4 (pinhole only).
    Equidistant([f32; 4]),
}

/// A calibrated camera and its corner noise.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct CameraSetup {
    /// Projection.
    pub projection: CameraProjection,
    /// `[fu, fv, cu, cv]`, pixels.
    pub intrinsics: [f32; 4],
    /// Distortion.
    pub distortion: CameraDistortion,
    /// `[width, height]`, pixels.
    pub resolution: [u32; 2],
    /// Corner noise, 1-sigma per axis, pixels.
    pub pixel_sigma: f32,
}

/// IMU prior at the first sample.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub enum ImuPrior {
    /// At rest (the host's standstill detection): the device levels the IMU on gravity.
    AtRest(RestPrior),
    /// The whole IMU state with its sigmas, as the host's start computed it (e.g. the
    /// monitor's dynamic alignment on a moving vehicle): nothing is re-derived on the device.
    State(ImuStart),
}

/// IMU at rest: gravity's direction and the gyro bias.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct RestPrior {
    /// Mean specific force at rest, m/s^2 (gives gravity's direction).
    pub accel_mean: [f32; 3],
    /// Gyro bias, rad/s.
    pub gyro_bias: [f32; 3],
    /// 1-sigma of roll/pitch/yaw, rad (0: the estimator's default).
    pub sigma_orientation_rad: f32,
    /// 1-sigma of the velocity, m/s (0: the estimator's default).
    pub sigma_velocity_m_s: f32,
}

/// An IMU state (`T_G_I`, velocity, biases) and its per-axis 1-sigmas.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct ImuStart {
    /// `q_G_I`, Hamilton `[w, x, y, z]`.
    pub rotation_wxyz: [f32; 4],
    /// `p_G_I`, m.
    pub position_m: [f32; 3],
    /// `v_G_I`, m/s.
    pub velocity_m_s: [f32; 3],
    /// Gyro bias, rad/s.
    pub gyro_bias_rad_s: [f32; 3],
    /// Accelerometer bias, m/s^2.
    pub accel_bias_m_s2: [f32; 3],
    /// 1-sigmas: orientation (rad), position (m), velocity (m/s), gyro bias (rad/s),
    /// accelerometer bias (m/s^2); each positive.
    pub sigmas: [f32; 5],
}

/// Filter configuration; (re)starts the filter.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Filter layout.
    pub sensors: SensorSet,
    /// IMU noise.
    pub imu_noise: ImuNoise,
    /// Gate of every update.
    pub gate: Gate,
    /// Largest IMU sample spacing, ns.
    pub max_imu_gap_ns: u32,
    /// IMU prior.
    pub imu_prior: ImuPrior,
    /// Prior of sensor 0 (the pose sensor, the camera, or the monitor's `pose0`).
    pub sensor: SensorPrior,
    /// Zero-velocity updates while IMU stamps are <= this (0: none), ns.
    pub zero_velocity_until_ns: u64,
    /// One zero-velocity update every this many IMU samples.
    pub zero_velocity_every: u16,
    /// An [`Estimate`] whenever filter time advanced by this much, ns (0: after each update).
    pub estimate_period_ns: u32,
}

/// One IMU sample of a batch.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Default)]
pub struct ImuSample {
    /// Stamp minus the batch's base stamp, ns.
    pub offset_ns: u32,
    /// Angular rate of `I` in `I`, rad/s.
    pub gyro: [f32; 3],
    /// Specific force in `I`, m/s^2.
    pub accel: [f32; 3],
}

/// Several IMU samples, stamped relative to a base.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct ImuBatch {
    /// Base stamp, ns.
    pub base_stamp_ns: u64,
    /// The samples.
    pub samples: Bounded<ImuSample, IMU_BATCH_MAX>,
}

/// Starts an odometry segment at a sensor stamp.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Anchor {
    /// Sensor stamp, ns.
    pub stamp_ns: u64,
    /// Pose sensor (0; 0 or 1 in the monitoring layout).
    pub sensor: u8,
}

/// Odometry increment `T_Sfrom_Sto` with a diagonal covariance.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct RelativePose {
    /// Sensor stamp of the start, ns.
    pub stamp_from_ns: u64,
    /// Sensor stamp of the end, ns.
    pub stamp_to_ns: u64,
    /// `T_Sfrom_Sto`.
    pub delta: Pose,
    /// 1-sigma of the rotation (right perturbation), rad, per axis.
    pub sigma_rotation_rad: [f32; 3],
    /// 1-sigma of the translation, m, per axis.
    pub sigma_translation_m: [f32; 3],
    /// Pose sensor (0; 0 or 1 in the monitoring layout).
    pub sensor: u8,
}

/// The target's pose in the camera in one image (the host's PnP), from which the device sets
/// the static target frame `T_G_T = T_G_I T_I_C T_C_T` when the IMU stream reaches the image.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct TargetPose {
    /// Image stamp (camera clock), ns.
    pub stamp_ns: u64,
    /// `T_cam_target`.
    pub t_cam_target: Pose,
    /// 1-sigma of the target frame's orientation, rad.
    pub sigma_rotation_rad: f32,
    /// 1-sigma of its position, m.
    pub sigma_position_m: f32,
}

/// One target corner detected in an image.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Default)]
pub struct Corner {
    /// Position in the target frame `T`, m.
    pub point_in_target_m: [f32; 3],
    /// Detected pixel `(u, v)` (centre of the top-left pixel = (0, 0)).
    pub pixel: [f32; 2],
}

/// Target corners detected in one image, fused as one reprojection update.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct CornerSet {
    /// Image stamp (camera clock), ns.
    pub stamp_ns: u64,
    /// The corners.
    pub corners: Bounded<Corner, CORNER_SET_MAX>,
}

/// What happened to a host frame.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AckStatus {
    /// Handled (its content may still have produced [`ErrorReport`]s).
    Ok,
    /// Sequence number already seen; ignored.
    Duplicate,
    /// Refused as a whole (see the [`ErrorReport`] sent before).
    Rejected,
}

/// Acknowledges host frame `seq`.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ack {
    /// Sequence number of the host frame.
    pub seq: u32,
    /// Outcome.
    pub status: AckStatus,
}

/// Windowed-NIS verdict of the health monitor.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum NisState {
    /// Window not full yet.
    Filling,
    /// Within the chi-square bounds.
    Consistent,
    /// Above: residuals larger than the model.
    High,
    /// Below: noise model too pessimistic.
    Low,
}

/// Health summary.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum HealthState {
    /// Not configured yet.
    Idle,
    /// Running, no alarm.
    Nominal,
    /// A [`HealthAlarm`] fired.
    Alarm,
}

/// Extrinsic estimate with sigmas.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Filter time (IMU clock), ns.
    pub stamp_ns: u64,
    /// `T_imu_sensor`.
    pub extrinsic: Pose,
    /// 1-sigma rotation per axis, rad.
    pub sigma_rotation_rad: [f32; 3],
    /// 1-sigma translation per axis, m.
    pub sigma_translation_m: [f32; 3],
    /// Time offset `t_d`, s.
    pub time_offset_s: f32,
    /// Its 1-sigma, s.
    pub sigma_time_offset_s: f32,
    /// Windowed NIS per degree of freedom.
    pub nis_per_dof: f32,
    /// Windowed-NIS verdict.
    pub nis_state: NisState,
    /// Health summary.
    pub health: HealthState,
    /// Alarms so far.
    pub alarms: u16,
    /// Updates accepted by the gate so far.
    pub updates_accepted: u32,
    /// Updates rejected by the gate so far.
    pub updates_rejected: u32,
    /// Sequence number of the last host frame applied before this estimate.
    pub last_seq: u32,
    /// The sensor whose extrinsic, time offset and NIS these are.
    pub sensor: u8,
}

/// Measurement model of an update.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpdateKind {
    /// Odometry increment.
    RelativePose,
    /// Zero velocity.
    ZeroVelocity,
    /// Target-corner reprojection.
    Reprojection,
    /// A LiDAR's board points against the target plane (joint calibration).
    BoardPlane,
}

/// Per-update record.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct UpdateDiagnostic {
    /// Measurement stamp (IMU clock), ns.
    pub stamp_ns: u64,
    /// Model.
    pub kind: UpdateKind,
    /// Degrees of freedom.
    pub dof: u8,
    /// Normalised innovation squared.
    pub nis: f32,
    /// Gate threshold.
    pub threshold: f32,
    /// Passed the gate.
    pub accepted: bool,
    /// The sensor measured; `None` for an update of no sensor (zero velocity).
    pub sensor: Option<u8>,
}

/// Which step the health monitor detected.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlarmKind {
    /// Extrinsic rotation changed.
    RotationStep,
    /// Extrinsic translation changed.
    TranslationStep,
}

/// The health monitor flagged a change of the extrinsic.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct HealthAlarm {
    /// Stamp of the triggering update (IMU clock), ns.
    pub stamp_ns: u64,
    /// Kind.
    pub kind: AlarmKind,
    /// GLR statistic (chi-square(3) under "no change").
    pub statistic: f32,
    /// Estimated step, rad or m.
    pub step: [f32; 3],
    /// The sensor whose extrinsic changed.
    pub sensor: u8,
}

/// Every fault the device counts. The discriminant is the index into [`Status::errors`].
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorKind {
    /// Malformed COBS, or a frame too short for a CRC.
    Framing,
    /// CRC mismatch.
    Crc,
    /// CRC fine but the postcard payload does not decode.
    Decode,
    /// Frame longer than the receive limit (dropped up to the next delimiter).
    Oversize,
    /// Receive ring full: bytes were lost.
    RxOverrun,
    /// Sequence numbers skipped (frames lost).
    SequenceGap,
    /// Sequence number seen before (frame ignored).
    Duplicate,
    /// Protocol version of a [`Hello`] differs.
    VersionMismatch,
    /// Measurement before a [`Config`].
    NotConfigured,
    /// Configuration refused by the filter.
    InvalidConfig,
    /// Too many pending pose messages.
    QueueFull,
    /// NaN or infinity in a measurement.
    NonFinite,
    /// Implausible value.
    OutOfRange,
    /// Stamp before the filter time.
    TimeWentBackwards,
    /// Gap in the IMU stream.
    ImuGap,
    /// Measurement before the first IMU sample.
    NotInitialized,
    /// Increment without a matching anchor (re-anchored).
    NoAnchor,
    /// Clone window full.
    CloneWindowFull,
    /// Innovation covariance not positive definite.
    SingularInnovation,
    /// Update diverged and was discarded.
    DivergentUpdate,
    /// Any other filter error.
    Other,
    /// Corner set before the target frame was initialised (no [`TargetPose`] applied).
    TargetNotInitialized,
    /// A corner falls behind the camera or outside the model's domain at the estimate.
    NotProjectable,
    /// Measurement of a sensor the configured [`SensorSet`] does not have (a camera
    /// message to a pose filter, odometry to a camera filter, a sensor index beyond the
    /// layout's).
    WrongSensorSet,
}

impl ErrorKind {
    /// Number of kinds (length of [`Status::errors`]).
    pub const COUNT: usize = 24;
    /// All kinds, in index order.
    pub const ALL: [ErrorKind; Self::COUNT] = [
        Self::Framing,
        Self::Crc,
        Self::Decode,
        Self::Oversize,
        Self::RxOverrun,
        Self::SequenceGap,
        Self::Duplicate,
        Self::VersionMismatch,
        Self::NotConfigured,
        Self::InvalidConfig,
        Self::QueueFull,
        Self::NonFinite,
        Self::OutOfRange,
        Self::TimeWentBackwards,
        Self::ImuGap,
        Self::NotInitialized,
        Self::NoAnchor,
        Self::CloneWindowFull,
        Self::SingularInnovation,
        Self::DivergentUpdate,
        Self::Other,
        Self::TargetNotInitialized,
        Self::NotProjectable,
        Self::WrongSensorSet,
    ];

    /// Index into [`Status::errors`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// snake_case name (logs, recordings).
    pub fn name(self) -> &'static str {
        [
            "framing",
            "crc",
            "decode",
            "oversize",
            "rx_overrun",
            "sequence_gap",
            "duplicate",
            "version_mismatch",
            "not_configured",
            "invalid_config",
            "queue_full",
            "non_finite",
            "out_of_range",
            "time_went_backwards",
            "imu_gap",
            "not_initialized",
            "no_anchor",
            "clone_window_full",
            "singular_innovation",
            "divergent_update",
            "other",
            "target_not_initialized",
            "not_projectable",
            "wrong_sensor_set",
        ][self.index()]
    }
}

/// A typed fault report.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ErrorReport {
    /// What.
    pub kind: ErrorKind,
    /// Running count of this kind, this one included.
    pub count: u32,
    /// Sequence number of the host frame concerned (0 when not known).
    pub seq: u32,
    /// Measurement stamp concerned (0 when none), ns.
    pub stamp_ns: u64,
}

/// Device counters and state.
#[derive(Serialize, Deserialize, MaxSize, Clone, Copy, Debug, PartialEq)]
pub struct Status {
    /// Filter configured.
    pub configured: bool,
    /// Filter time, ns.
    pub filter_time_ns: u64,
    /// Frames decoded.
    pub frames_ok: u32,
    /// Last host sequence number applied.
    pub last_seq: u32,
    /// IMU samples propagated.
    pub imu_samples: u32,
    /// Anchors set.
    pub anchors: u32,
    /// Relative-pose or reprojection updates (accepted or gated out).
    pub updates: u32,
    /// Zero-velocity updates.
    pub zero_velocity_updates: u32,
    /// Fault counters, indexed by [`ErrorKind::index`].
    pub errors: [u32; ErrorKind::COUNT],
}
