//! A session with the firmware over a serial port: replay a dataset (drive, odometry or
//! camera corners), and re-open a recording.

use std::path::Path;
use std::time::{Duration, Instant};

use msreg_protocol::{DeviceMsg, HostMsg, Status, TimeBase};

use super::client::{Client, ClientOptions, Collected, TimedExchange};
use super::clock_sync::{ClockFit, ClockSync, ClockSyncOptions, Exchange};
use super::monitor_stream::build_monitor_stream;
use super::record::{self, Line};
use super::stamp_map::StampMap;
use super::stream::{build_camera_stream, build_stream, ReplayStream, StreamOptions};
use super::view::{summary, LiveView, Mode};
use super::LinkError;
use crate::calibrate::camera_imu::{detect_corner_frames, CameraImuInput, CameraImuOptions};
use crate::calibrate::pose_imu::PoseImuInput;
use crate::dataset::Dataset;
use crate::monitor::{DriveFiles, MonitorOptions};
use crate::vision::frames::CameraDataset;

/// Options of [`replay`].
#[derive(Debug, Clone, Copy, Default)]
pub struct ReplayOptions {
    /// Pace at the data rate.
    pub realtime: bool,
    /// Stream options.
    pub stream: StreamOptions,
    /// Client options.
    pub client: ClientOptions,
    /// Draw the live screen while streaming when stdout is a terminal.
    pub live_view: bool,
    /// Clock sync.
    pub sync: SyncOptions,
}

/// Clock sync of a replay (docs/protocol.md, "Clock sync").
#[derive(Debug, Clone, Copy)]
pub struct SyncOptions {
    /// Exchanges before streaming (0: no clock sync at all).
    pub initial: usize,
    /// One exchange per this much wall time while streaming.
    pub period: Duration,
    /// The estimator's tuning.
    pub estimator: ClockSyncOptions,
    /// Map the stamps onto the device clock whatever the device says (a stand-in for a
    /// device that reads its sensors on its own clock); `None`: as the device's reply says.
    pub time_base: Option<TimeBase>,
}

impl Default for SyncOptions {
    fn default() -> Self {
        Self {
            initial: 16,
            period: Duration::from_secs(1),
            estimator: ClockSyncOptions::default(),
            time_base: None,
        }
    }
}

/// What a replay produced.
#[derive(Debug, Clone)]
pub struct ReplayOutcome {
    /// Everything the device sent.
    pub collected: Collected,
    /// Device status at the end.
    pub status: Option<Status>,
    /// Frames sent.
    pub frames: u64,
    /// Bytes sent.
    pub bytes: u64,
    /// Wall time of the streaming, s.
    pub elapsed_s: f64,
    /// First IMU stamp of the dataset, ns.
    pub start_ns: u64,
    /// The last clock-sync fit (host clock: ns since the session started), if any exchange
    /// was answered.
    pub clock: Option<ClockFit>,
    /// The clock the stamps were sent on.
    pub time_base: Option<TimeBase>,
}

/// The replay's clock sync: the estimator over the client's own clock (ns since the
/// session started).
struct ReplayClock {
    sync: ClockSync,
    epoch: Instant,
    time_base: Option<TimeBase>,
}

impl ReplayClock {
    fn host_ns(&self, at: Instant) -> i64 {
        at.saturating_duration_since(self.epoch).as_nanos() as i64
    }

    /// One exchange into the estimator (a lost or refused one is skipped).
    fn exchange(&mut self, client: &mut Client) -> Result<(), LinkError> {
        if let Some(TimedExchange {
            sent,
            received,
            reply,
        }) = client.time_sync(Duration::from_millis(500))?
        {
            self.time_base.get_or_insert(reply.time_base);
            let e = Exchange {
                t1_ns: self.host_ns(sent),
                t2_ns: reply.t2_ns as i64,
                t3_ns: reply.t3_ns as i64,
                t4_ns: self.host_ns(received),
            };
            let _ = self.sync.add(e);
        }
        Ok(())
    }
}

/// The replay of a dataset: a drive (`pose0/` and `pose1/`) to the monitoring layout, as
/// `msreg monitor` runs it; odometry when it has `pose0/` only; else target corners of `cam0/`.
pub fn dataset_stream(dataset: &Path, options: &StreamOptions) -> Result<ReplayStream, LinkError> {
    if dataset.join("pose1").is_dir() {
        let files = DriveFiles::read(dataset, None)?;
        let input = files.input()?;
        return build_monitor_stream(&input, &MonitorOptions::default(), options);
    }
    let data = Dataset::open(dataset)?;
    let imu = data.require_imu()?;
    let imu_noise = data.require_imu_noise()?;
    if data.pose0.is_some() || !dataset.join("cam0").is_dir() {
        let input = PoseImuInput {
            imu,
            imu_noise,
            poses: data.require_pose0()?,
            pose_noise: data.require_pose0_sensor()?,
        };
        return build_stream(&input, options);
    }
    let camera = CameraDataset::open(dataset)?;
    let (frames, detection) =
        detect_corner_frames(&camera, &crate::vision::DetectorParams::default(), &|_| {})?;
    eprintln!(
        "msreg: board found in {} of {} images ({:.1} s)",
        detection.detected, detection.images, detection.time_s
    );
    let input = CameraImuInput {
        imu,
        imu_noise,
        camera: &camera.camera,
        frames: &frames,
    };
    build_camera_stream(&input, &CameraImuOptions::default(), options)
}

/// Replays `dataset` to the device at `port`.
pub fn replay(
    dataset: &Path,
    port: &str,
    record: Option<&Path>,
    options: &ReplayOptions,
) -> Result<ReplayOutcome, LinkError> {
    let stream = dataset_stream(dataset, &options.stream)?;
    replay_stream(
        &stream,
        &dataset.display().to_string(),
        port,
        record,
        options,
    )
}

/// Sends a replay stream (handshake, configuration, messages) to the device at `port`;
/// `source` names the data on the live screen.
pub fn replay_stream(
    stream: &ReplayStream,
    source: &str,
    port: &str,
    record: Option<&Path>,
    options: &ReplayOptions,
) -> Result<ReplayOutcome, LinkError> {
    let mut client = Client::connect(port, options.client, record.map(|r| (r, "replay")))?;
    client.handshake(Duration::from_secs(10))?;
    let mut clock = ReplayClock {
        sync: ClockSync::new(options.sync.estimator),
        epoch: Instant::now(),
        time_base: options.sync.time_base,
    };
    for _ in 0..options.sync.initial {
        clock.exchange(&mut client)?;
    }
    let on_device = clock.time_base == Some(TimeBase::DeviceClock) && clock.sync.fit().is_some();
    client.send(&HostMsg::Config(stream.config))?;
    let started = Instant::now();
    let mut last_sync = started;
    let mut stamps = StampMap::new();
    // The data clock on the host: the dataset's time, run from `started` on (paced).
    let data_epoch_ns = clock.host_ns(started);
    let (frames0, bytes0) = client.sent;
    // On a terminal the replay shows the monitor's screen while it streams.
    let mut view = (options.live_view && Mode::detect() == Mode::Screen)
        .then(|| LiveView::new(Mode::Screen, &format!("replay {source} -> {port}")));
    for (stamp_ns, msg) in &stream.messages {
        // Device-clock stamps mean what they say only at the data's own pace.
        if options.realtime || on_device {
            let due = Duration::from_nanos(stamp_ns.saturating_sub(stream.start_ns));
            while started.elapsed() < due {
                client.pump(Duration::from_millis(1))?;
            }
        }
        if options.sync.initial > 0 && last_sync.elapsed() >= options.sync.period {
            last_sync = Instant::now();
            clock.exchange(&mut client)?;
        }
        match clock.sync.fit().filter(|_| on_device) {
            Some(fit) => {
                let start_ns = stream.start_ns;
                let to_device = move |s: u64| {
                    let host = data_epoch_ns + s.saturating_sub(start_ns) as i64;
                    fit.to_device(host).max(0) as u64
                };
                client.send(&stamps.message(msg, &to_device))?;
            }
            None => {
                client.send(msg)?;
            }
        }
        if let Some(text) = view
            .as_mut()
            .and_then(|v| v.frame(&client.collected, client.now_s()))
        {
            use std::io::Write;
            let mut out = std::io::stdout();
            let _ = out.write_all(text.as_bytes()).and_then(|()| out.flush());
        }
    }
    client.flush(Duration::from_secs(10))?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let status = client.status(Duration::from_secs(5)).ok();
    client.pump(Duration::from_millis(50))?;
    client.finish()?;
    Ok(ReplayOutcome {
        collected: client.collected.clone(),
        status,
        frames: client.sent.0 - frames0,
        bytes: client.sent.1 - bytes0,
        elapsed_s,
        start_ns: stream.start_ns,
        clock: clock.sync.fit(),
        time_base: clock.time_base,
    })
}

/// Re-opens a recording and summarises it.
pub fn show(file: &Path) -> Result<String, LinkError> {
    let lines = record::read(file)?;
    let mut c = Collected::default();
    let mut status = None;
    let (mut tx, mut header) = (0usize, None);
    for line in &lines {
        match line {
            Line::Header { header: h } => header = Some(h.clone()),
            Line::Tx { .. } => tx += 1,
            Line::Bad { .. } => c.bad_frames += 1,
            Line::Rx { t, rx } => match rx.msg {
                DeviceMsg::Hello(h) => c.hello = Some(h),
                DeviceMsg::Ack(a) => c.acks[a.status as usize] += 1,
                DeviceMsg::Estimate(e) => c.estimates.push((*t, e)),
                DeviceMsg::UpdateDiagnostic(d) => c.diagnostics.push((*t, d)),
                DeviceMsg::HealthAlarm(a) => c.alarms.push((*t, a)),
                DeviceMsg::ErrorReport(e) => c.errors.push((*t, e)),
                DeviceMsg::Status(s) => status = Some(s),
                DeviceMsg::TimeSync(r) => c.time_syncs.push((*t, r)),
            },
        }
    }
    let mut out = match header {
        Some(h) => format!(
            "{}: `{}` session on {} (protocol v{}), {} lines, {} host frames recorded\n",
            file.display(),
            h.command,
            h.port,
            h.protocol_version,
            lines.len(),
            tx
        ),
        None => format!("{}: no header\n", file.display()),
    };
    out.push_str(&summary(&c, status.as_ref()));
    Ok(out)
}
