//! `msreg link replay | monitor | show`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Subcommand;
use msreg_host::link::client::{Client, ClientOptions};
use msreg_host::link::clock_sync::ClockSyncOptions;
use msreg_host::link::defmt;
use msreg_host::link::view::{LiveView, Mode};
use msreg_host::link::{replay, show, summary, ReplayOptions, StreamOptions, SyncOptions};

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
        /// Map every stamp onto the device clock (clock sync), whatever the device's time
        /// base says (docs/protocol.md "Clock sync").
        #[arg(long)]
        device_clock: bool,
        /// Known floor asymmetry of the link (forward minus backward floor), us; 0 on a direct
        /// UART (every stamp is at a frame's first byte).
        #[arg(long, default_value_t = 0.0)]
        sync_asymmetry_us: f64,
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
            device_clock,
            sync_asymmetry_us,
        } => {
            let options = ReplayOptions {
                realtime,
                stream: StreamOptions {
                    batch,
                    estimate_period_ns: (estimate_period_ms * 1e6).clamp(0.0, 4.0e9) as u32,
                    ..StreamOptions::default()
                },
                live_view: true,
                sync: SyncOptions {
                    time_base: device_clock.then_some(msreg_protocol::TimeBase::DeviceClock),
                    estimator: ClockSyncOptions {
                        asymmetry_ns: (sync_asymmetry_us * 1e3) as i64,
                        ..ClockSyncOptions::default()
                    },
                    ..SyncOptions::default()
                },
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
            if let Some(c) = &outcome.clock {
                println!(
                    "clock sync: device - host offset {:.3} ms, skew {:+.1} ppm (sigma {:.3} ms, \
                     {:.1} ppm; path asymmetry bound {:.3} ms) from {} exchanges",
                    c.offset_ns * 1e-6,
                    c.skew * 1e6,
                    c.sigma_ns * 1e-6,
                    c.sigma_skew * 1e6,
                    c.asymmetry_bound_ns * 1e-6,
                    c.exchanges
                );
            }
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
