//! `msreg link replay | monitor | show`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Subcommand;
use msreg_protocol::{DeviceMsg, ErrorKind, HealthState, HostMsg, Status};

use super::client::{Client, ClientOptions, Collected};
use super::defmt;
use super::monitor_stream::build_monitor_stream;
use super::record::{self, Line};
use super::stream::{build_camera_stream, build_stream, ReplayStream, StreamOptions};
use super::view::{rpy_deg, LiveView, Mode};
use super::LinkError;
use crate::calibrate::camera_imu::cli::detect_corner_frames;
use crate::calibrate::camera_imu::{CameraImuInput, CameraImuOptions};
use crate::calibrate::pose_imu::PoseImuInput;
use crate::dataset::Dataset;
use crate::monitor::DriveFiles;
use crate::monitor::MonitorOptions;
use crate::vision::frames::CameraDataset;

/// `msreg link ...`.
#[derive(Debug, Subcommand)]
pub enum LinkCommand {
    /// Stream a dataset to the firmware and record its answers: a drive (pose0/ and pose1/,
    /// calibration.yaml) to the device's health monitor, started as `msreg monitor` starts;
    /// IMU + odometry increments (pose0/ only); or IMU + target corners (cam0/ and
    /// target.yaml, no pose0/): the corners are detected and MoCal runs here, the device runs
    /// RepErrCal.
    Replay {
        /// Dataset directory (imu0/ with pose0/ and pose1/, imu0/ with pose0/, or imu0/ with
        /// cam0/ and target.yaml).
        dataset: PathBuf,
        /// Serial device (e.g. the /dev/pts/N QEMU prints).
        #[arg(long)]
        port: String,
        /// Pace the stream at the dataset's own rate instead of as fast as the link allows.
        #[arg(long)]
        realtime: bool,
        /// Session recording (JSON lines).
        #[arg(long, default_value = "link-replay.jsonl")]
        record: PathBuf,
        /// Estimate period, ms (0: after every update).
        #[arg(long, default_value_t = 0.0)]
        estimate_period_ms: f64,
        /// IMU samples per frame (1-16).
        #[arg(long, default_value_t = 10)]
        batch: usize,
    },
    /// Show live estimates, sigmas, NIS and health from a running device.
    Monitor {
        /// Serial device.
        #[arg(long)]
        port: String,
        /// Stop after this many seconds (default: until interrupted).
        #[arg(long)]
        duration: Option<f64>,
        /// Session recording (JSON lines).
        #[arg(long, default_value = "link-monitor.jsonl")]
        record: PathBuf,
    },
    /// Summarise a recorded session.
    Show {
        /// Recording written by `replay` or `monitor`.
        file: PathBuf,
    },
    /// Decode the firmware's defmt log (QEMU's stdout under semihosting), e.g.
    /// `qemu-system-arm ... -serial pty -kernel ELF | msreg link log --elf ELF`.
    Log {
        /// The firmware ELF that produced the log (its `.defmt` symbols hold the texts).
        #[arg(long)]
        elf: PathBuf,
        /// Raw log file (default: standard input, decoded as it arrives).
        input: Option<PathBuf>,
    },
}

/// Runs a `link` subcommand.
pub fn run(command: LinkCommand) -> anyhow::Result<()> {
    match command {
        LinkCommand::Replay {
            dataset,
            port,
            realtime,
            record,
            estimate_period_ms,
            batch,
        } => {
            let options = ReplayOptions {
                realtime,
                stream: StreamOptions {
                    batch,
                    estimate_period_ns: (estimate_period_ms * 1e6).clamp(0.0, 4.0e9) as u32,
                    ..StreamOptions::default()
                },
                live_view: true,
                ..ReplayOptions::default()
            };
            let outcome = replay(&dataset, &port, Some(&record), &options)?;
            print!("{}", summary(&outcome.collected, outcome.status.as_ref()));
            println!(
                "link: {} frames, {} bytes in {:.2} s = {:.0} frames/s, {:.1} kB/s; recorded to {}",
                outcome.frames,
                outcome.bytes,
                outcome.elapsed_s,
                outcome.frames as f64 / outcome.elapsed_s.max(1e-9),
                outcome.bytes as f64 / outcome.elapsed_s.max(1e-9) / 1e3,
                record.display()
            );
            Ok(())
        }
        LinkCommand::Monitor {
            port,
            duration,
            record,
        } => monitor(&port, duration, &record),
        LinkCommand::Show { file } => {
            print!("{}", show(&file)?);
            Ok(())
        }
        LinkCommand::Log { elf, input } => log(&elf, input.as_deref()),
    }
}

/// Decodes a defmt log stream and prints one line per frame as it arrives.
fn log(elf: &Path, input: Option<&Path>) -> anyhow::Result<()> {
    use std::io::{Read, Write};
    let table = defmt::Table::from_elf(elf)?;
    let mut stream = defmt::Stream::new(table);
    let mut source: Box<dyn Read> = match input {
        Some(p) => {
            Box::new(std::fs::File::open(p).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?)
        }
        None => Box::new(std::io::stdin()),
    };
    let mut out = std::io::stdout().lock();
    let mut buf = [0u8; 4096];
    loop {
        let n = match source.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e.into()),
        };
        for d in stream.push(&buf[..n]) {
            match d {
                defmt::Decoded::Log(l) => writeln!(out, "{l}")?,
                defmt::Decoded::Text(t) => writeln!(out, "(host) {t}")?,
                defmt::Decoded::Bad(why) => writeln!(out, "(undecodable frame: {why})")?,
            }
        }
        out.flush()?;
    }
    Ok(())
}

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
    client.send(&HostMsg::Config(stream.config))?;
    let started = Instant::now();
    let (frames0, bytes0) = client.sent;
    // On a terminal the replay shows the monitor's screen while it streams.
    let mut view = (options.live_view && Mode::detect() == Mode::Screen)
        .then(|| LiveView::new(Mode::Screen, &format!("replay {source} -> {port}")));
    for (stamp_ns, msg) in &stream.messages {
        if options.realtime {
            let due = Duration::from_nanos(stamp_ns.saturating_sub(stream.start_ns));
            while started.elapsed() < due {
                client.pump(Duration::from_millis(1))?;
            }
        }
        client.send(msg)?;
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
    })
}

fn monitor(port: &str, duration: Option<f64>, record: &Path) -> anyhow::Result<()> {
    use std::io::Write;
    let mut client = Client::connect(port, ClientOptions::default(), Some((record, "monitor")))?;
    client.handshake(Duration::from_secs(10))?;
    let started = Instant::now();
    let mut view = LiveView::new(Mode::detect(), port);
    let mut out = std::io::stdout();
    loop {
        client.pump(Duration::from_millis(100))?;
        if let Some(text) = view.frame(&client.collected, client.now_s()) {
            out.write_all(text.as_bytes())?;
            out.flush()?;
        }
        if duration.is_some_and(|d| started.elapsed().as_secs_f64() >= d) {
            break;
        }
    }
    client.finish()?;
    Ok(())
}

/// A few lines a person can read at a glance: estimate, sigmas, NIS, health, faults.
pub fn live_view(c: &Collected) -> String {
    match c.estimates.last() {
        Some((t, e)) => estimate_line(c, *t, e),
        None => format!(
            "t {:>7.2} s | waiting for estimates | errors {}",
            c.errors.last().map_or(0.0, |x| x.0),
            c.errors.len()
        ),
    }
}

/// The last estimate of every sensor that sent one, a line each (one sensor: as
/// [`live_view`]).
pub fn final_estimates(c: &Collected) -> String {
    let mut sensors: Vec<u8> = c.estimates.iter().map(|(_, e)| e.sensor).collect();
    sensors.sort_unstable();
    sensors.dedup();
    if sensors.len() < 2 {
        return live_view(c);
    }
    sensors
        .iter()
        .filter_map(|s| c.estimates.iter().rev().find(|(_, e)| e.sensor == *s))
        .map(|(t, e)| format!("pose{}: {}", e.sensor, estimate_line(c, *t, e)))
        .collect::<Vec<_>>()
        .join("\n")
}

fn estimate_line(c: &Collected, t: f64, e: &msreg_protocol::Estimate) -> String {
    let mut out = String::new();
    let r = rpy_deg(e);
    let sr = e.sigma_rotation_rad.map(|s| f64::from(s).to_degrees());
    let health = match e.health {
        HealthState::Alarm => "ALARM",
        HealthState::Nominal => "ok",
        HealthState::Idle => "idle",
    };
    out.push_str(&format!(
        "t {t:>7.2} s | rpy {:>8.3} {:>8.3} {:>8.3} deg (+-{:.3} {:.3} {:.3}) | xyz {:>7.4} {:>7.4} {:>7.4} m (+-{:.4} {:.4} {:.4}) | td {:>6.2} ms (+-{:.2}) | NIS/dof {:.2} {:?} | health {health} ({} alarms) | upd {}/{} | errors {}",
        r[0], r[1], r[2], sr[0], sr[1], sr[2],
        e.extrinsic.translation_m[0], e.extrinsic.translation_m[1], e.extrinsic.translation_m[2],
        e.sigma_translation_m[0], e.sigma_translation_m[1], e.sigma_translation_m[2],
        e.time_offset_s * 1e3, e.sigma_time_offset_s * 1e3,
        e.nis_per_dof, e.nis_state, e.alarms,
        e.updates_accepted, e.updates_accepted + e.updates_rejected,
        c.errors.len(),
    ));
    out
}

fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// Multi-line summary of a session.
pub fn summary(c: &Collected, status: Option<&Status>) -> String {
    let mut out = String::new();
    out.push_str(&format!("{}\n", final_estimates(c)));
    out.push_str(&format!(
        "device: {} estimates, {} update diagnostics, {} alarms, {} error reports; acks ok/dup/rejected {}/{}/{}, ack timeouts {}, bad frames {}\n",
        c.estimates.len(), c.diagnostics.len(), c.alarms.len(), c.errors.len(),
        c.acks[0], c.acks[1], c.acks[2], c.ack_timeouts, c.bad_frames
    ));
    for (t, a) in &c.alarms {
        out.push_str(&format!(
            "alarm at host t {t:.2} s: {:?} of sensor {} at stamp {} ns, statistic {:.1}\n",
            a.kind, a.sensor, a.stamp_ns, a.statistic
        ));
    }
    if let Some(s) = status {
        out.push_str(&format!(
            "status: configured {}, {} frames, {} IMU samples, {} anchors, {} updates, {} zero-velocity\n",
            s.configured, s.frames_ok, s.imu_samples, s.anchors, s.updates, s.zero_velocity_updates
        ));
        let faults: Vec<String> = ErrorKind::ALL
            .iter()
            .filter(|k| s.errors[k.index()] > 0)
            .map(|k| format!("{} {}", k.name(), s.errors[k.index()]))
            .collect();
        out.push_str(&format!(
            "fault counters: {}\n",
            if faults.is_empty() {
                "none".to_string()
            } else {
                faults.join(", ")
            }
        ));
    }
    if !c.ack_latency_s.is_empty() {
        out.push_str(&format!(
            "ack round trip: median {:.2} ms, p95 {:.2} ms; estimate latency: median {:.2} ms, p95 {:.2} ms\n",
            percentile(&c.ack_latency_s, 0.5) * 1e3,
            percentile(&c.ack_latency_s, 0.95) * 1e3,
            percentile(&c.estimate_latency_s, 0.5) * 1e3,
            percentile(&c.estimate_latency_s, 0.95) * 1e3
        ));
    }
    out
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
