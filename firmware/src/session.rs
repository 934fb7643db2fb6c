//! The link session: applies decoded host packets to the f32 filter, in order, and answers
//! through any `embedded_io::Write`. Independent of the board.
//!
//! Sequencing follows the host pipelines (`host/src/calibrate/pose_imu.rs`,
//! `camera_imu.rs`, `monitor/replay.rs`): pose messages (one queue per pose sensor; of the
//! due ones the earliest IMU time goes first), target poses and corner sets wait in bounded
//! queues until
//! the IMU stream reaches their IMU time `stamp + t_d` (with the current `t_d` estimate) and
//! are applied just before the IMU sample that passes it; an increment without a matching
//! anchor re-anchors at its end, as the host does; a target pose initialises the target
//! frame `T_G_T = T_G_I T_I_C T_C_T` at the current IMU state, as the host's RepErrCal.
//! Every refusal is counted by [`ErrorKind`] and reported; nothing resets the device.
//! Log lines (`defmt`, typed primitive arguments only: see `msreg link log`) mark the
//! configuration, each fault, each alarm and the progress every [`PROGRESS_PERIOD_NS`].
//!
//! Clock sync: a `TimeSync` request is answered with the device clock when its frame's
//! first byte arrived (the caller's receive stamp) and just before the reply is written,
//! ahead of its ack. This firmware's IMU arrives over the link, so its filter runs on the
//! host's stamps ([`TIME_BASE`]).

use heapless::Deque;
use msreg_estimator::health::{HealthEvent, NisStatus};
use msreg_estimator::na::{Matrix6, Vector2, Vector3};
use msreg_estimator::{
    CornerObservation, Error as FilterError, ImuSample, Pose, RelativePose as FilterRelativePose,
    SensorId, UpdateReport,
};
use msreg_protocol::{
    self as protocol, frame, Ack, AckStatus, AlarmKind, Anchor, Config, CornerSet, DeviceMsg,
    ErrorKind, ErrorReport, Estimate, FrameError, HealthAlarm, HealthState, Hello, HostMsg,
    ImuBatch, NisState, Packet, RelativePose, Status, TargetPose, TimeBase, TimeSyncReply,
    TimeSyncRequest, UpdateDiagnostic, UpdateKind, CORNER_SET_MAX, DEVICE_FRAME_MAX,
    HOST_FRAME_MAX,
};

pub use crate::filter::POSE_SENSORS;
pub use crate::filter::{configure, Filter};
use crate::filter::{pose, CameraFilter, SENSOR, TARGET};

/// Pose messages per sensor that may wait for the IMU stream.
pub const PENDING_MAX: usize = 16;
/// Camera messages (target pose, corner sets) that may wait for the IMU stream: each entry
/// is a full corner set in RAM (~1 KB); the host sends them 60 ms ahead of the IMU batch at
/// their stamp, so at 20 Hz at most three images and the target pose wait (docs/protocol.md).
pub const CAMERA_PENDING_MAX: usize = 4;
/// The clock the filter runs on: the IMU comes over the link, stamped by the host.
pub const TIME_BASE: TimeBase = TimeBase::HostStamps;
/// Filter time between two progress log lines.
pub const PROGRESS_PERIOD_NS: u64 = 5_000_000_000;

#[derive(Clone, Copy)]
enum Pending {
    Anchor(Anchor, u32),
    Increment(RelativePose, u32),
}

impl Pending {
    fn stamp_ns(&self) -> u64 {
        match self {
            Pending::Anchor(a, _) => a.stamp_ns,
            Pending::Increment(r, _) => r.stamp_to_ns,
        }
    }

    fn sensor(&self) -> u8 {
        match self {
            Pending::Anchor(a, _) => a.sensor,
            Pending::Increment(r, _) => r.sensor,
        }
    }
}

/// A camera message waiting for the IMU stream, with its frame's sequence number.
#[derive(Clone, Copy)]
#[allow(
    clippy::large_enum_variant,
    reason = "no heap: the queue's 4 fixed slots hold corner sets by value, sized for them"
)]
enum CameraPending {
    Target(TargetPose, u32),
    Corners(CornerSet, u32),
}

impl CameraPending {
    fn stamp_ns(&self) -> u64 {
        match self {
            CameraPending::Target(t, _) => t.stamp_ns,
            CameraPending::Corners(c, _) => c.stamp_ns,
        }
    }

    fn seq(&self) -> u32 {
        match self {
            CameraPending::Target(_, s) | CameraPending::Corners(_, s) => *s,
        }
    }

    /// Every value finite, sigmas positive.
    fn check(&self) -> Result<(), ErrorKind> {
        let in_range = match self {
            CameraPending::Target(t, _) => {
                let p = &t.t_cam_target;
                let sigmas = [t.sigma_rotation_rad, t.sigma_position_m];
                if !p
                    .rotation_wxyz
                    .iter()
                    .chain(&p.translation_m)
                    .chain(&sigmas)
                    .all(|x| x.is_finite())
                {
                    return Err(ErrorKind::NonFinite);
                }
                sigmas.iter().all(|s| *s > 0.0)
            }
            CameraPending::Corners(c, _) => {
                if !c.corners.as_slice().iter().all(|k| {
                    k.point_in_target_m
                        .iter()
                        .chain(&k.pixel)
                        .all(|x| x.is_finite())
                }) {
                    return Err(ErrorKind::NonFinite);
                }
                !c.corners.is_empty()
            }
        };
        if in_range {
            Ok(())
        } else {
            Err(ErrorKind::OutOfRange)
        }
    }
}

/// Counters of the session.
#[derive(Clone, Copy, Default)]
struct Counts {
    frames_ok: u32,
    imu_samples: u32,
    anchors: u32,
    updates: u32,
    accepted: u32,
    rejected: u32,
    zero_velocity: u32,
    /// Alarms per sensor.
    alarms: [u16; POSE_SENSORS],
    errors: [u32; ErrorKind::COUNT],
}

/// Session state. Large (it holds the filter): keep it in a `static` (`new` is `const`).
///
/// Stack: the filter calls run in their own non-inlined functions (`#[inline(never)]` on
/// the handlers), so their multi-kilobyte frames exist only while they run. Inlined into
/// one caller, LLVM gave `main` a single 39 KB frame holding all of them at once.
pub struct Session {
    filter: Option<Filter>,
    config: Option<Config>,
    /// One queue per pose sensor: each is in stamp order, the sensors' due times interleave.
    pending: [Deque<Pending, PENDING_MAX>; POSE_SENSORS],
    camera_pending: Deque<CameraPending, CAMERA_PENDING_MAX>,
    counts: Counts,
    last_seq: Option<u32>,
    tx_seq: u32,
    imu_index: u32,
    last_estimate_ns: u64,
    last_progress_ns: u64,
    /// Filter time of the first sample after the configuration (progress lines count from it).
    progress_origin_ns: u64,
    /// Per sensor: an alarm was raised since the configuration.
    alarm: [bool; POSE_SENSORS],
    /// Sequence number of the frame being applied (estimates carry it, for latency).
    current_seq: u32,
}

impl Default for Session {
    fn default() -> Self {
        Self::new()
    }
}

/// Where answers go; write errors are ignored (nothing else could be done with them).
pub struct Tx<'a, W: embedded_io::Write> {
    writer: &'a mut W,
    seq: &'a mut u32,
}

impl<W: embedded_io::Write> Tx<'_, W> {
    #[inline(never)]
    fn send(&mut self, msg: &DeviceMsg) {
        let mut buf = [0u8; DEVICE_FRAME_MAX];
        if let Ok(n) = frame::encode(*self.seq, msg, &mut buf) {
            *self.seq = self.seq.wrapping_add(1);
            let _ = self.writer.write_all(&buf[..n]);
        }
    }
}

impl Session {
    /// Not configured.
    pub const fn new() -> Self {
        Self {
            filter: None,
            config: None,
            pending: [Deque::new(), Deque::new()],
            camera_pending: Deque::new(),
            counts: Counts {
                frames_ok: 0,
                imu_samples: 0,
                anchors: 0,
                updates: 0,
                accepted: 0,
                rejected: 0,
                zero_velocity: 0,
                alarms: [0; POSE_SENSORS],
                errors: [0; ErrorKind::COUNT],
            },
            last_seq: None,
            tx_seq: 0,
            imu_index: 0,
            last_estimate_ns: 0,
            last_progress_ns: 0,
            progress_origin_ns: 0,
            alarm: [false; POSE_SENSORS],
            current_seq: 0,
        }
    }

    fn tx<'a, W: embedded_io::Write>(seq: &'a mut u32, writer: &'a mut W) -> Tx<'a, W> {
        Tx { writer, seq }
    }

    /// The handshake message of this device.
    pub fn hello() -> Hello {
        Hello {
            version: protocol::VERSION,
            max_frame: HOST_FRAME_MAX as u16,
            rx_buffer: crate::uart::RX_RING as u16,
        }
    }

    /// Announces the device (at boot).
    pub fn announce<W: embedded_io::Write>(&mut self, w: &mut W) {
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::Hello(Self::hello()));
    }

    /// Counts and reports a fault.
    pub fn fault<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        kind: ErrorKind,
        seq: u32,
        stamp_ns: u64,
    ) {
        let count = &mut self.counts.errors[kind.index()];
        *count = count.saturating_add(1);
        defmt::warn!(
            "fault {=str} (#{=u32}), frame {=u32}, stamp {=u64} ns",
            kind.name(),
            *count,
            seq,
            stamp_ns
        );
        let report = ErrorReport {
            kind,
            count: *count,
            seq,
            stamp_ns,
        };
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::ErrorReport(report));
    }

    /// A frame that failed to decode.
    pub fn frame_error<W: embedded_io::Write>(&mut self, w: &mut W, e: FrameError) {
        let kind = match e {
            FrameError::Crc => ErrorKind::Crc,
            FrameError::Decode => ErrorKind::Decode,
            FrameError::Oversize => ErrorKind::Oversize,
            FrameError::Framing | FrameError::BufferTooSmall => ErrorKind::Framing,
        };
        self.fault(w, kind, 0, 0);
    }

    /// Bytes lost in the receive ring.
    pub fn overrun<W: embedded_io::Write>(&mut self, w: &mut W, bytes: u32) {
        if bytes > 0 {
            self.fault(w, ErrorKind::RxOverrun, 0, u64::from(bytes));
        }
    }

    /// Applies one decoded packet and acknowledges it. `rx_ns`: the device clock when the
    /// frame's first byte arrived; `clock`: the device clock now (ns, the same clock).
    #[inline(never)]
    pub fn handle<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        packet: Packet<HostMsg>,
        rx_ns: u64,
        clock: fn() -> u64,
    ) {
        let seq = packet.seq;
        let is_hello = matches!(packet.msg, HostMsg::Hello(_));
        if !is_hello {
            if let Some(last) = self.last_seq {
                let ahead = seq.wrapping_sub(last);
                if ahead == 0 || ahead > u32::MAX / 2 {
                    self.fault(w, ErrorKind::Duplicate, seq, 0);
                    self.ack(w, seq, AckStatus::Duplicate);
                    return;
                }
                if ahead > 1 {
                    self.fault(w, ErrorKind::SequenceGap, seq, u64::from(ahead - 1));
                }
            }
        }
        self.last_seq = Some(seq);
        self.current_seq = seq;
        self.counts.frames_ok = self.counts.frames_ok.wrapping_add(1);
        // By reference: a by-value corner set would put a second copy (~1 KB) in this
        // frame, which every handler's stack sits on.
        let status = match &packet.msg {
            HostMsg::Hello(h) => self.on_hello(w, seq, h),
            HostMsg::Config(c) => self.on_config(w, seq, c),
            HostMsg::ImuBatch(b) => self.on_imu(w, seq, b),
            HostMsg::Anchor(a) => self.on_pose(w, seq, Pending::Anchor(*a, seq)),
            HostMsg::RelativePose(r) => self.on_pose(w, seq, Pending::Increment(*r, seq)),
            HostMsg::TargetPose(t) => self.on_camera(w, seq, CameraPending::Target(*t, seq)),
            HostMsg::CornerSet(c) => self.on_camera(w, seq, CameraPending::Corners(*c, seq)),
            HostMsg::GetStatus => {
                let status = DeviceMsg::Status(self.status());
                Self::tx(&mut self.tx_seq, w).send(&status);
                AckStatus::Ok
            }
            HostMsg::TimeSync(r) => self.on_time_sync(w, r, rx_ns, clock),
        };
        self.ack(w, seq, status);
    }

    /// The reply of a clock-sync exchange: `t3` is read last, just before the encoding (a
    /// few microseconds) and the write.
    fn on_time_sync<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        r: &TimeSyncRequest,
        rx_ns: u64,
        clock: fn() -> u64,
    ) -> AckStatus {
        let reply = TimeSyncReply {
            t1_ns: r.t1_ns,
            t2_ns: rx_ns,
            t3_ns: clock(),
            time_base: TIME_BASE,
        };
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::TimeSync(reply));
        AckStatus::Ok
    }

    fn ack<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, status: AckStatus) {
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::Ack(Ack { seq, status }));
    }

    fn on_hello<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, h: &Hello) -> AckStatus {
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::Hello(Self::hello()));
        if h.version != protocol::VERSION {
            self.fault(w, ErrorKind::VersionMismatch, seq, u64::from(h.version));
            return AckStatus::Rejected;
        }
        AckStatus::Ok
    }

    #[inline(never)]
    fn on_config<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, c: &Config) -> AckStatus {
        match configure(&mut self.filter, c) {
            Ok(()) => {
                self.config = Some(*c);
                self.pending.iter_mut().for_each(Deque::clear);
                self.camera_pending.clear();
                self.imu_index = 0;
                self.last_estimate_ns = 0;
                self.last_progress_ns = 0;
                self.alarm = [false; POSE_SENSORS];
                defmt::info!(
                    "configured: {=u32} sensor(s), estimate every {=u32} ns, sigma prior {=f32} rad / {=f32} m",
                    self.filter.as_ref().map_or(0, Filter::sensor_count) as u32,
                    c.estimate_period_ns,
                    c.sensor.sigma_rotation_rad,
                    c.sensor.sigma_translation_m
                );
                let errors = self.counts.errors;
                self.counts = Counts {
                    errors,
                    frames_ok: self.counts.frames_ok,
                    ..Counts::default()
                };
                AckStatus::Ok
            }
            Err(_) => {
                self.fault(w, ErrorKind::InvalidConfig, seq, 0);
                AckStatus::Rejected
            }
        }
    }

    /// The ack of a queued measurement: rejected with a fault report when `refused`.
    fn acknowledge<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        refused: Option<ErrorKind>,
        seq: u32,
        stamp_ns: u64,
    ) -> AckStatus {
        match refused {
            Some(kind) => {
                self.fault(w, kind, seq, stamp_ns);
                AckStatus::Rejected
            }
            None => AckStatus::Ok,
        }
    }

    fn on_pose<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, p: Pending) -> AckStatus {
        let refused = match &self.filter {
            None => Some(ErrorKind::NotConfigured),
            // The wire's sensor becomes an id of the configured layout here, or is refused.
            Some(f) => match f.sensor_id(p.sensor()) {
                Ok(s) if f.takes_odometry() => match self.pending.get_mut(s.index()) {
                    Some(queue) => queue.push_back(p).err().map(|_| ErrorKind::QueueFull),
                    None => Some(ErrorKind::WrongSensorSet),
                },
                Ok(_) | Err(_) => Some(ErrorKind::WrongSensorSet),
            },
        };
        self.acknowledge(w, refused, seq, p.stamp_ns())
    }

    #[inline(never)]
    fn on_camera<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        seq: u32,
        p: CameraPending,
    ) -> AckStatus {
        let refused = match self.filter {
            None => Some(ErrorKind::NotConfigured),
            Some(Filter::PoseImu(_) | Filter::Monitor(_)) => Some(ErrorKind::WrongSensorSet),
            Some(Filter::CameraImu(_)) => match p.check() {
                Err(kind) => Some(kind),
                Ok(()) => self
                    .camera_pending
                    .push_back(p)
                    .err()
                    .map(|_| ErrorKind::QueueFull),
            },
        };
        self.acknowledge(w, refused, seq, p.stamp_ns())
    }

    #[inline(never)]
    fn on_imu<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, b: &ImuBatch) -> AckStatus {
        if self.filter.is_none() {
            self.fault(w, ErrorKind::NotConfigured, seq, b.base_stamp_ns);
            return AckStatus::Rejected;
        }
        for s in b.samples.as_slice() {
            let Some(stamp_ns) = b.base_stamp_ns.checked_add(u64::from(s.offset_ns)) else {
                self.fault(w, ErrorKind::OutOfRange, seq, b.base_stamp_ns);
                continue;
            };
            let sample = ImuSample {
                stamp_ns,
                gyro: Vector3::from(s.gyro),
                accel: Vector3::from(s.accel),
            };
            if self.apply_imu(w, seq, &sample) == Err(ErrorKind::NotConfigured) {
                return AckStatus::Rejected;
            }
        }
        self.periodic_estimate(w, seq);
        self.progress();
        AckStatus::Ok
    }

    /// One IMU sample into the filter: propagation, the zero-velocity update, then the
    /// measurements it made due; a refusal is reported as a fault and returned.
    fn apply_imu<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        seq: u32,
        sample: &ImuSample<f32>,
    ) -> Result<(), ErrorKind> {
        let Some(filter) = self.filter.as_mut() else {
            return Err(ErrorKind::NotConfigured);
        };
        match filter.propagate(sample) {
            Ok(()) => {
                self.counts.imu_samples += 1;
                self.zero_velocity(w, seq, sample.stamp_ns);
                self.imu_index += 1;
                // The sample is the filter's look-ahead: what it makes due can be fused.
                self.apply_due(w);
                Ok(())
            }
            Err(e) => {
                let kind = error_kind(&e);
                self.fault(w, kind, seq, sample.stamp_ns);
                Err(kind)
            }
        }
    }

    /// Feeds one IMU sample measured on the device (a board's IMU driver, stamped on the
    /// device clock) as a host `ImuBatch` sample is fed: propagation, zero-velocity update,
    /// due measurements, periodic estimate, progress line. Before a configuration the
    /// sample is dropped without a report (the IMU runs from boot): `Err(NotConfigured)`.
    #[inline(never)]
    pub fn local_imu<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        sample: &ImuSample<f32>,
    ) -> Result<(), ErrorKind> {
        if self.filter.is_none() {
            return Err(ErrorKind::NotConfigured);
        }
        let seq = self.current_seq;
        let applied = self.apply_imu(w, seq, sample);
        self.periodic_estimate(w, seq);
        self.progress();
        applied
    }

    /// A log line every [`PROGRESS_PERIOD_NS`] of filter time.
    fn progress(&mut self) {
        let Some(f) = self.filter.as_ref() else {
            return;
        };
        let now = f.time_ns();
        if now < self.last_progress_ns.saturating_add(PROGRESS_PERIOD_NS) {
            return;
        }
        if self.last_progress_ns == 0 {
            // First sample: start the clock, nothing to report yet.
            self.last_progress_ns = now;
            self.progress_origin_ns = now;
            return;
        }
        self.last_progress_ns = now;
        let (sr, st) = f.extrinsic_sigma(SENSOR);
        defmt::info!(
            "t {=u64} ms: {=u32} IMU samples, {=u32} updates ({=u32} accepted), sigma {=f32} deg / {=f32} mm",
            now.saturating_sub(self.progress_origin_ns) / 1_000_000,
            self.counts.imu_samples,
            self.counts.updates,
            self.counts.accepted,
            sr.max() * 57.29578,
            st.max() * 1000.0
        );
    }

    /// True when a measurement of sensor `s` stamped `stamp_ns` (sensor clock) can be
    /// fused: the filter holds an IMU sample at or after its IMU time (`Ekf::is_due`).
    fn is_due(&self, s: SensorId, stamp_ns: u64) -> bool {
        self.filter.as_ref().is_some_and(|f| f.is_due(s, stamp_ns))
    }

    /// The pose sensor whose queue front is due with the earliest IMU time (ties: the lower
    /// index), as `msreg monitor` orders the two sensors.
    fn earliest_due_pose(&self) -> Option<SensorId> {
        let f = self.filter.as_ref()?;
        f.sensor_ids()
            .filter_map(|s| {
                let front = self.pending[s.index()].front()?;
                let stamp = front.stamp_ns();
                if !f.is_due(s, stamp) {
                    return None;
                }
                f.imu_time(s, stamp).ok().map(|t| (t, s))
            })
            .min()
            .map(|(_, s)| s)
    }

    /// Applies every pending measurement that the newest IMU sample made due.
    fn apply_due<W: embedded_io::Write>(&mut self, w: &mut W) {
        self.apply_due_poses(w);
        self.apply_due_camera(w);
    }

    /// Not inlined: the popped entry (~1 KB) stays out of `on_imu`'s frame, below which the
    /// pose updates run.
    #[inline(never)]
    fn apply_due_camera<W: embedded_io::Write>(&mut self, w: &mut W) {
        while let Some(front) = self.camera_pending.front() {
            if !self.is_due(SENSOR, front.stamp_ns()) {
                return;
            }
            let Some(front) = self.camera_pending.pop_front() else {
                return;
            };
            if self.imu_index == 0 {
                self.fault(w, ErrorKind::NotInitialized, front.seq(), front.stamp_ns());
                continue;
            }
            match &front {
                CameraPending::Target(t, seq) => self.init_target(w, t, *seq),
                CameraPending::Corners(c, seq) => self.corners(w, c, *seq),
            }
        }
    }

    fn apply_due_poses<W: embedded_io::Write>(&mut self, w: &mut W) {
        while let Some(s) = self.earliest_due_pose() {
            let Some(front) = self.pending[s.index()].pop_front() else {
                return;
            };
            if self.imu_index == 0 {
                self.fault(
                    w,
                    ErrorKind::NotInitialized,
                    seq_of(&front),
                    front.stamp_ns(),
                );
                continue;
            }
            match front {
                Pending::Anchor(a, seq) => self.anchor(w, s, a.stamp_ns, seq),
                Pending::Increment(r, seq) => self.increment(w, s, &r, seq),
            }
        }
    }

    /// `T_G_T = T_G_I T_I_C T_C_T` at the image's IMU time, with its cross-covariance with
    /// the IMU pose, the extrinsic and the time offset (`Ekf::init_frame_relative`); the
    /// message's sigmas are those of the measured `T_C_T` (independent per axis).
    #[inline(never)]
    fn init_target<W: embedded_io::Write>(&mut self, w: &mut W, t: &TargetPose, seq: u32) {
        let Some(Filter::CameraImu(CameraFilter { ekf, .. })) = self.filter.as_mut() else {
            return;
        };
        let (r, p) = (t.sigma_rotation_rad, t.sigma_position_m);
        let cov = nalgebra::SMatrix::<f32, 6, 6>::from_diagonal(&nalgebra::SVector::from([
            r * r,
            r * r,
            r * r,
            p * p,
            p * p,
            p * p,
        ]));
        match ekf.init_frame_relative(TARGET, SENSOR, t.stamp_ns, &pose(&t.t_cam_target), &cov) {
            Ok(()) => defmt::info!(
                "target initialised at {=u64} ns, {=f32} m from the camera",
                t.stamp_ns,
                Vector3::from(t.t_cam_target.translation_m).norm()
            ),
            Err(e) => self.fault(w, error_kind(&e), seq, t.stamp_ns),
        }
    }

    /// One reprojection update with the corners of an image.
    #[inline(never)]
    fn corners<W: embedded_io::Write>(&mut self, w: &mut W, c: &CornerSet, seq: u32) {
        let Some(Filter::CameraImu(CameraFilter {
            ekf,
            camera,
            pixel_sigma,
        })) = self.filter.as_mut()
        else {
            return;
        };
        let mut buffer = [CornerObservation {
            point_in_target: Vector3::zeros(),
            pixel: Vector2::zeros(),
        }; CORNER_SET_MAX];
        for (slot, k) in buffer.iter_mut().zip(c.corners.as_slice()) {
            slot.point_in_target = Vector3::from(k.point_in_target_m);
            slot.pixel = Vector2::from(k.pixel);
        }
        let meas = msreg_estimator::CornerSet {
            stamp_ns: c.stamp_ns,
            corners: &buffer[..c.corners.len()],
            pixel_sigma: *pixel_sigma,
        };
        match ekf.update_reprojection(SENSOR, TARGET, camera, &meas) {
            Ok(report) => self.on_report(w, &report, seq),
            Err(e) => self.fault(w, error_kind(&e), seq, c.stamp_ns),
        }
    }

    #[inline(never)]
    fn anchor<W: embedded_io::Write>(&mut self, w: &mut W, s: SensorId, stamp_ns: u64, seq: u32) {
        let Some(filter) = self.filter.as_mut() else {
            return;
        };
        match filter.anchor(s, stamp_ns) {
            Ok(()) => self.counts.anchors += 1,
            Err(e) => self.fault(w, error_kind(&e), seq, stamp_ns),
        }
    }

    #[inline(never)]
    fn increment<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        s: SensorId,
        r: &RelativePose,
        seq: u32,
    ) {
        let Some(filter) = self.filter.as_mut() else {
            return;
        };
        let meas = relative_pose(r);
        match filter.update_relative_pose(s, &meas) {
            Ok(report) => self.on_report(w, &report, seq),
            Err(e @ (FilterError::NoAnchor | FilterError::OlderThanWindow)) => {
                // The chain broke (a lost or refused pose): start a new segment here.
                self.fault(w, error_kind(&e), seq, r.stamp_to_ns);
                self.anchor(w, s, r.stamp_to_ns, seq);
            }
            Err(e) => self.fault(w, error_kind(&e), seq, r.stamp_to_ns),
        }
    }

    #[inline(never)]
    fn zero_velocity<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, stamp_ns: u64) {
        let Some(c) = self.config else { return };
        let every = u32::from(c.zero_velocity_every.max(1));
        if stamp_ns > c.zero_velocity_until_ns || !self.imu_index.is_multiple_of(every) {
            return;
        }
        let Some(filter) = self.filter.as_mut() else {
            return;
        };
        // As on the host: the first sample gives the stream no period yet (no ZUPT then); a
        // gated-out update is a diagnostic, an error is a fault.
        if filter.imu_period_ns().is_none() {
            return;
        }
        match filter.update_zero_velocity() {
            Ok(report) => {
                self.counts.zero_velocity += 1;
                let diag = diagnostic(&report);
                Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::UpdateDiagnostic(diag));
            }
            Err(e) => self.fault(w, error_kind(&e), seq, stamp_ns),
        }
    }

    fn on_report<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        report: &UpdateReport<f32>,
        _frame_seq: u32,
    ) {
        self.counts.updates += 1;
        if report.accepted {
            self.counts.accepted += 1;
        } else {
            self.counts.rejected += 1;
        }
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::UpdateDiagnostic(diagnostic(report)));
        if let Some(event) = &report.event {
            let a = alarm(event);
            let s = usize::from(a.sensor);
            if let (Some(flag), Some(count)) =
                (self.alarm.get_mut(s), self.counts.alarms.get_mut(s))
            {
                *flag = true;
                *count = count.saturating_add(1);
            }
            defmt::warn!(
                "health alarm {=str} of sensor {=u8} at {=u64} ns: statistic {=f32}",
                match a.kind {
                    AlarmKind::RotationStep => "rotation step",
                    AlarmKind::TranslationStep => "translation step",
                },
                a.sensor,
                a.stamp_ns,
                a.statistic
            );
            Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::HealthAlarm(a));
        }
        if self.config.is_some_and(|c| c.estimate_period_ns == 0) {
            self.send_estimate(w, self.current_seq, report.sensor.unwrap_or(SENSOR));
        }
    }

    fn periodic_estimate<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32) {
        let (Some(c), Some(f)) = (self.config, self.filter.as_ref()) else {
            return;
        };
        let (now, sensors) = (f.time_ns(), f.sensor_ids());
        if c.estimate_period_ns > 0
            && now
                >= self
                    .last_estimate_ns
                    .saturating_add(u64::from(c.estimate_period_ns))
        {
            for s in sensors {
                self.send_estimate(w, seq, s);
            }
        }
    }

    /// The estimate of sensor `s`.
    #[inline(never)]
    fn send_estimate<W: embedded_io::Write>(&mut self, w: &mut W, seq: u32, s: SensorId) {
        let Some(f) = self.filter.as_ref() else {
            return;
        };
        self.last_estimate_ns = f.time_ns();
        let alarm = self.alarm.get(s.index()).copied().unwrap_or(false);
        let e = estimate(f, &self.counts, alarm, seq, s);
        Self::tx(&mut self.tx_seq, w).send(&DeviceMsg::Estimate(e));
    }

    /// Counters and state.
    pub fn status(&self) -> Status {
        Status {
            configured: self.filter.is_some(),
            filter_time_ns: self.filter.as_ref().map_or(0, Filter::time_ns),
            frames_ok: self.counts.frames_ok,
            last_seq: self.last_seq.unwrap_or(0),
            imu_samples: self.counts.imu_samples,
            anchors: self.counts.anchors,
            updates: self.counts.updates,
            zero_velocity_updates: self.counts.zero_velocity,
            errors: self.counts.errors,
        }
    }
}

fn seq_of(p: &Pending) -> u32 {
    match p {
        Pending::Anchor(_, s) | Pending::Increment(_, s) => *s,
    }
}

fn wire_pose(p: &Pose<f32>) -> protocol::Pose {
    let q = p.rotation.quaternion();
    protocol::Pose {
        rotation_wxyz: [q.w, q.i, q.j, q.k],
        translation_m: p.translation.into(),
    }
}

fn relative_pose(r: &RelativePose) -> FilterRelativePose<f32> {
    let mut covariance = Matrix6::zeros();
    for i in 0..3 {
        covariance[(i, i)] = r.sigma_rotation_rad[i] * r.sigma_rotation_rad[i];
        covariance[(i + 3, i + 3)] = r.sigma_translation_m[i] * r.sigma_translation_m[i];
    }
    FilterRelativePose {
        stamp_from_ns: r.stamp_from_ns,
        stamp_to_ns: r.stamp_to_ns,
        delta: pose(&r.delta),
        covariance,
    }
}

fn error_kind(e: &FilterError) -> ErrorKind {
    match e {
        FilterError::NonFinite => ErrorKind::NonFinite,
        FilterError::OutOfRange => ErrorKind::OutOfRange,
        FilterError::TimeWentBackwards { .. } => ErrorKind::TimeWentBackwards,
        FilterError::ImuGap { .. } => ErrorKind::ImuGap,
        FilterError::NotInitialized => ErrorKind::NotInitialized,
        FilterError::NoAnchor | FilterError::OlderThanWindow => ErrorKind::NoAnchor,
        FilterError::CloneWindowFull => ErrorKind::CloneWindowFull,
        FilterError::SingularInnovation => ErrorKind::SingularInnovation,
        FilterError::DivergentUpdate => ErrorKind::DivergentUpdate,
        FilterError::InvalidConfig => ErrorKind::InvalidConfig,
        FilterError::FrameNotInitialized => ErrorKind::TargetNotInitialized,
        FilterError::NotProjectable => ErrorKind::NotProjectable,
        FilterError::EmptyMeasurement => ErrorKind::OutOfRange,
        // The session names its sensor and target itself and fuses only what is due: only a
        // bug could make these.
        FilterError::UnknownSensor | FilterError::UnknownFrame | FilterError::NotYetDue { .. } => {
            ErrorKind::Other
        }
    }
}

fn diagnostic(r: &UpdateReport<f32>) -> UpdateDiagnostic {
    UpdateDiagnostic {
        stamp_ns: r.stamp_ns,
        kind: match r.kind {
            msreg_estimator::UpdateKind::ZeroVelocity => UpdateKind::ZeroVelocity,
            msreg_estimator::UpdateKind::Reprojection => UpdateKind::Reprojection,
            msreg_estimator::UpdateKind::RelativePose => UpdateKind::RelativePose,
            msreg_estimator::UpdateKind::BoardPlane => UpdateKind::BoardPlane,
        },
        dof: r.dof as u8,
        nis: r.nis,
        threshold: r.threshold,
        accepted: r.accepted,
        sensor: r.sensor.map(SensorId::wire),
    }
}

fn alarm(e: &HealthEvent<f32>) -> HealthAlarm {
    match *e {
        HealthEvent::RotationStep {
            sensor,
            stamp_ns,
            statistic,
            step,
            ..
        } => HealthAlarm {
            stamp_ns,
            kind: AlarmKind::RotationStep,
            statistic,
            step: step.into(),
            sensor: sensor.wire(),
        },
        HealthEvent::TranslationStep {
            sensor,
            stamp_ns,
            statistic,
            step,
            ..
        } => HealthAlarm {
            stamp_ns,
            kind: AlarmKind::TranslationStep,
            statistic,
            step: step.into(),
            sensor: sensor.wire(),
        },
    }
}

fn estimate(f: &Filter, c: &Counts, alarm: bool, seq: u32, s: SensorId) -> Estimate {
    let (sr, st) = f.extrinsic_sigma(s);
    let (nis_per_dof, nis_state) = f.nis(s).map_or((0.0, NisState::Filling), |(nis, status)| {
        let state = match status {
            NisStatus::Filling => NisState::Filling,
            NisStatus::Consistent => NisState::Consistent,
            NisStatus::High => NisState::High,
            NisStatus::Low => NisState::Low,
        };
        (nis, state)
    });
    Estimate {
        stamp_ns: f.time_ns(),
        extrinsic: wire_pose(&f.extrinsic(s)),
        sigma_rotation_rad: sr.into(),
        sigma_translation_m: st.into(),
        time_offset_s: f.time_offset(s),
        sigma_time_offset_s: f.time_offset_sigma(s),
        nis_per_dof,
        nis_state,
        health: if alarm {
            HealthState::Alarm
        } else {
            HealthState::Nominal
        },
        alarms: c.alarms.get(s.index()).copied().unwrap_or(0),
        updates_accepted: c.accepted,
        updates_rejected: c.rejected,
        last_seq: seq,
        sensor: s.wire(),
    }
}
