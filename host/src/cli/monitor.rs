//! `msreg monitor <dataset>`: the command-line face of [`msreg_host::monitor::monitor`].
//!
//! Exit codes: 0 when the replay ran, alarms or not (finding a knock is the monitor doing its
//! job; the alarms are printed and in the report); with `--fail-on-alarm`, 1 when an alarm
//! was raised; 1 when the filter could not be started; 2 on bad input.

use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;
use msreg_estimator::chi2::Confidence;

use msreg_host::monitor::{monitor, DriveFiles, MonitorOptions, MonitorReport};

/// `msreg monitor`.
#[derive(Debug, Args)]
pub struct MonitorArgs {
    /// Dataset directory: imu0/, pose0/, pose1/ (CONVENTIONS.md).
    pub dataset: PathBuf,
    /// The calibration of record (a result file with `pose0` and `pose1` sections); default
    /// `<dataset>/calibration.yaml`.
    #[arg(long)]
    pub initial: Option<PathBuf>,
    /// Timeline plot (SVG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Exit 1 when an alarm was raised.
    #[arg(long)]
    pub fail_on_alarm: bool,
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

/// How the command ended, for the exit code.
#[derive(Debug, Clone, PartialEq)]
pub enum MonitorOutcome {
    /// Ran; no alarm, or alarms without `--fail-on-alarm`.
    Ran,
    /// Alarms with `--fail-on-alarm`, or the filter could not start (the reason).
    Failed(String),
}

/// Runs the command; bad input is an `Err` (exit 2).
pub fn run(args: &MonitorArgs) -> anyhow::Result<MonitorOutcome> {
    let files = DriveFiles::read(&args.dataset, args.initial.as_deref())?;
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
        Err(e) if e.is_no_start() => return Ok(MonitorOutcome::Failed(e.to_string())),
        Err(e) => return Err(anyhow!("{}: {e}", args.dataset.display())),
    };
    print_report(&report);
    write_outputs(args, &report)?;
    Ok(if args.fail_on_alarm && !report.alarms.is_empty() {
        MonitorOutcome::Failed(format!("{} alarm(s) raised", report.alarms.len()))
    } else {
        MonitorOutcome::Ran
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
