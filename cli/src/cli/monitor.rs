//! `msreg monitor <dataset|bag|mcap>`: the command-line face of
//! [`msreg_host::monitor::monitor`], ending with the verdict in words
//! ([`msreg_host::monitor::Verdict`]).
//!
//! Exit codes (docs/monitor.md): 0 the replay ran and no calibration changed; 3 a
//! calibration changed (an alarm was raised; the verdict says which sensor and what to do);
//! 1 the filter could not be started on this recording; 2 bad input (naming the file).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};
use clap::Args;
use msreg_estimator::chi2::Confidence;

use super::outcome::progress_bar;
use msreg_host::bag::TopicChoice;
use msreg_host::dataset::{ImuNoiseYaml, PoseSensorYaml};
use msreg_host::monitor::drive_bag::{convert_drive, DriveTopics};
use msreg_host::monitor::{monitor, DriveFiles, MonitorOptions, MonitorReport, VerdictWords};

/// Exit code when a sensor's calibration changed (an alarm was raised).
pub const EXIT_CALIBRATION_CHANGED: i32 = 3;

/// `msreg monitor`.
///
/// Exit codes: 0 no calibration changed; 3 a calibration changed (alarm); 1 the filter
/// could not start on this recording; 2 bad input.
#[derive(Debug, Args)]
#[command(
    after_help = "Exit codes: 0 no calibration changed; 3 a calibration changed (an \
alarm was raised: the VERDICT line names the sensor, the axis, the angle and what to do); 1 \
the filter could not start on this recording; 2 bad input (the file and line are named). \
docs/monitor.md has the details."
)]
pub struct MonitorArgs {
    /// Dataset directory (imu0/ and the pose sensors pose0/ ... poseN-1/, one to four of them;
    /// docs/formats.md), or a ROS 1 `.bag` / `.mcap` file with `--pose0 TOPIC [--pose1 TOPIC]`
    /// (and `--initial`).
    pub dataset: PathBuf,
    /// The calibration of record (a result file with a `poseN` section per pose sensor);
    /// default `<dataset>/calibration.yaml`; required with a bag.
    #[arg(long)]
    pub initial: Option<PathBuf>,
    /// Timeline plot (SVG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write the re-estimated calibration (every sensor's final estimate with its sigmas, in
    /// the result file's sections `pose0`, `pose1`, ..., one per pose sensor) to this file.
    #[arg(long)]
    pub write_calibration: Option<PathBuf>,
    /// Accepted for old scripts; an alarm now always exits 3.
    #[arg(long, hide = true)]
    pub fail_on_alarm: bool,
    /// With a bag: IMU topic (sensor_msgs/Imu); default: the only one.
    #[arg(long)]
    pub imu: Option<String>,
    /// With a bag: the first pose sensor's topic (nav_msgs/Odometry, PoseStamped, ...).
    #[arg(long)]
    pub pose0: Option<String>,
    /// With a bag: the second pose sensor's topic (optional: without it the monitor watches
    /// one pose sensor).
    #[arg(long)]
    pub pose1: Option<String>,
    /// With a bag: Kalibr imu.yaml with the IMU's noise figures (default: docs/bags.md).
    #[arg(long)]
    pub imu_config: Option<PathBuf>,
    /// With a bag: pose0's sensor.yaml (increment noise; default: docs/bags.md).
    #[arg(long)]
    pub pose0_config: Option<PathBuf>,
    /// With a bag: pose1's sensor.yaml.
    #[arg(long)]
    pub pose1_config: Option<PathBuf>,
    /// Confidence of the step detectors' threshold per test (the false-alarm rate per hour
    /// of driving it gives is in docs/monitor.md, "False alarms"); default as `MonitorOptions`.
    #[arg(long, value_enum)]
    pub step_confidence: Option<StepConfidence>,
    /// Forgetting factor of the step detectors per update; default as `MonitorOptions`.
    #[arg(long)]
    pub step_forgetting: Option<f64>,
}

/// `--step-confidence`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StepConfidence {
    /// 99.9 %.
    #[value(name = "99.9")]
    P999,
    /// 99.99 %.
    #[value(name = "99.99")]
    P9999,
    /// 99.999 %.
    #[value(name = "99.999")]
    P99999,
}

impl From<StepConfidence> for Confidence {
    fn from(c: StepConfidence) -> Self {
        match c {
            StepConfidence::P999 => Confidence::P999,
            StepConfidence::P9999 => Confidence::P9999,
            StepConfidence::P99999 => Confidence::P99999,
        }
    }
}

/// How the command ended, for the exit code (main.rs).
#[derive(Debug, Clone, PartialEq)]
pub enum MonitorOutcome {
    /// Ran; no calibration changed.
    Ran,
    /// The filter could not start (the reason).
    Failed(String),
}

/// What the monitor found.
#[derive(Debug, Clone, PartialEq)]
pub enum Finding {
    /// Ran; no calibration changed (exit 0).
    Healthy,
    /// A sensor's calibration changed (exit [`EXIT_CALIBRATION_CHANGED`]).
    Changed,
    /// The filter could not start (exit 1), with the reason.
    NoStart(String),
}

/// Runs the command; bad input is an `Err` (exit 2). A changed calibration exits
/// [`EXIT_CALIBRATION_CHANGED`] here, after every output is written.
pub fn run(args: &MonitorArgs) -> anyhow::Result<MonitorOutcome> {
    match check(args)? {
        Finding::Healthy => Ok(MonitorOutcome::Ran),
        Finding::NoStart(why) => Ok(MonitorOutcome::Failed(why)),
        Finding::Changed => {
            let _ = std::io::stdout().flush();
            std::process::exit(EXIT_CALIBRATION_CHANGED)
        }
    }
}

/// Whether `path` is a ROS 1 bag or an MCAP file (by its extension; the readers check the
/// magic bytes).
fn is_bag(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("bag") || e.eq_ignore_ascii_case("mcap"))
}

/// The bag's topics and noise files from the flags.
fn drive_topics(args: &MonitorArgs) -> anyhow::Result<DriveTopics> {
    let topic = |flag: &Option<String>, name: &str| {
        flag.clone().ok_or_else(|| {
            anyhow!(
                "{}: a bag needs --{name} TOPIC (which pose topic is which sensor)",
                args.dataset.display()
            )
        })
    };
    let pose_noise = |p: &Option<PathBuf>| p.as_ref().map(PoseSensorYaml::read).transpose();
    if args.pose1.is_none() && args.pose1_config.is_some() {
        bail!(
            "{}: --pose1-config without --pose1 TOPIC",
            args.dataset.display()
        );
    }
    let mut poses = vec![topic(&args.pose0, "pose0")?];
    poses.extend(args.pose1.clone());
    Ok(DriveTopics {
        imu: TopicChoice::from_flag(args.imu.as_deref()),
        poses,
        imu_noise: args
            .imu_config
            .as_ref()
            .map(ImuNoiseYaml::read)
            .transpose()?,
        pose_noise: vec![
            pose_noise(&args.pose0_config)?,
            pose_noise(&args.pose1_config)?,
        ],
    })
}

/// The drive's files: the directory, or the bag converted into `scratch` (its topics are the
/// sensors' labels).
fn drive_files(
    args: &MonitorArgs,
    scratch: &Path,
) -> anyhow::Result<(DriveFiles, Vec<Option<String>>)> {
    let bag_flags = [&args.imu, &args.pose0, &args.pose1]
        .iter()
        .any(|f| f.is_some())
        || [&args.imu_config, &args.pose0_config, &args.pose1_config]
            .iter()
            .any(|f| f.is_some());
    if !is_bag(&args.dataset) {
        if bag_flags {
            bail!(
                "{}: --imu, --pose0, --pose1 and their --*-config apply to a .bag or .mcap \
                 file; this is not one",
                args.dataset.display()
            );
        }
        let files = DriveFiles::read(&args.dataset, args.initial.as_deref())?;
        let labels = vec![None; files.pose_sensors()];
        return Ok((files, labels));
    }
    let Some(initial) = &args.initial else {
        bail!(
            "{}: a bag carries no calibration of record: give it with --initial calibration.yaml",
            args.dataset.display()
        );
    };
    let topics = drive_topics(args)?;
    let dir = scratch.join("drive");
    let bar = progress_bar(1000, "{spinner} reading [{bar:40}] {percent}% {elapsed}");
    let summaries = convert_drive(&args.dataset, &topics, &dir, &mut |f| {
        bar.set_position((f * 1000.0) as u64)
    });
    bar.finish_and_clear();
    let summaries = summaries.with_context(|| format!("converting {}", args.dataset.display()))?;
    for w in summaries.iter().flat_map(|s| &s.warnings) {
        eprintln!("msreg: warning: {w}");
    }
    let files = DriveFiles::read(&dir, Some(initial))?;
    Ok((files, topics.poses.into_iter().map(Some).collect()))
}

/// Runs the monitor, prints the report and the verdict, writes the outputs.
pub fn check(args: &MonitorArgs) -> anyhow::Result<Finding> {
    let scratch = tempfile::Builder::new()
        .prefix("msreg-monitor-")
        .tempdir()?;
    let (files, labels) = drive_files(args, scratch.path())?;
    let input = files.input()?;
    let mut options = MonitorOptions::default();
    if let Some(c) = args.step_confidence {
        options.step_confidence = c.into();
    }
    if let Some(l) = args.step_forgetting {
        if !(l > 0.0 && l <= 1.0) {
            return Err(anyhow!("--step-forgetting {l}: must be in (0, 1]"));
        }
        options.step_forgetting = l;
    }
    let report = match monitor(&input, &options) {
        Ok(r) => r,
        Err(e) if e.is_no_start() => return Ok(Finding::NoStart(e.to_string())),
        Err(e) => return Err(anyhow!("{}: {e}", args.dataset.display())),
    };
    print_report(&report);
    write_outputs(args, &report)?;
    let verdict = report.verdict();
    let words = VerdictWords {
        labels,
        calibration_out: args
            .write_calibration
            .as_ref()
            .map(|p| p.display().to_string()),
    };
    for line in verdict.lines(&words) {
        println!("VERDICT {line}");
    }
    Ok(if verdict.changed() {
        Finding::Changed
    } else {
        Finding::Healthy
    })
}

fn write_outputs(args: &MonitorArgs, report: &MonitorReport) -> anyhow::Result<()> {
    if let Some(path) = &args.report {
        let timeline = msreg_host::report::SvgFigure {
            id: "fig-monitor-timeline".into(),
            caption: "Timeline: NIS per sensor, alarms, per-DoF excitation".into(),
            svg: msreg_host::monitor::timeline::timeline_svg(report),
        };
        msreg_host::report::write_report_with_figures(path, report, &[], &[timeline])?;
        eprintln!("msreg: wrote {}", path.display());
    }
    if let Some(path) = &args.plot {
        msreg_host::monitor::timeline::write_timeline_svg(path, report)?;
        eprintln!("msreg: wrote {}", path.display());
    }
    if let Some(path) = &args.write_calibration {
        report.calibration().write(path)?;
        eprintln!("msreg: wrote {}", path.display());
    }
    Ok(())
}

/// Alarms, per-sensor summary and the unobservable DoFs on stdout.
pub fn print_report(r: &MonitorReport) {
    println!(
        "monitor: {:.1} s replayed; IMU start: {}",
        r.duration_s, r.start
    );
    if let (Some(a), Some(q)) = (r.planar_axis, r.planar_axis_ratio) {
        println!(
            "planar motion: rotation axis [{:.3}, {:.3}, {:.3}] (IMU frame), axis ratio {q:.3}",
            a[0], a[1], a[2]
        );
    }
    if r.alarms.is_empty() {
        println!("alarms: none");
    }
    for a in &r.alarms {
        println!(
            "ALARM {:8.2} s  {}  {}  statistic {:.1}  step [{:.3}, {:.3}, {:.3}] {}",
            a.t_s,
            a.sensor,
            a.kind,
            a.statistic,
            a.step[0],
            a.step[1],
            a.step[2],
            if a.kind == "translation_step" {
                "mm"
            } else {
                "deg"
            }
        );
    }
    for w in &r.warnings {
        println!(
            "warning {:6.2} s  {}  {}  windowed NIS/dof {:.2}",
            w.t_s, w.sensor, w.kind, w.statistic
        );
    }
    for s in &r.sensors {
        println!(
            "{}: {} updates fused, {} rejected by the gate, {} held out while a knock candidate was tested, {} skipped; final estimate moved {:.3} deg, {:.1} mm from the calibration of record",
            s.name,
            s.accepted,
            s.rejected,
            s.held_out,
            s.skipped.len(),
            s.rotation_change_deg,
            s.translation_change_m * 1e3
        );
    }
    for w in r.unobservable_words() {
        println!("{w}");
    }
}
