//! `msreg monitor <dataset>`: the command-line face of [`msreg_host::monitor::monitor`].
//!
//! Exit codes: 0 when the replay ran, alarms or not (finding a knock is the monitor doing its
//! job; the alarms are printed and in the report); with `--fail-on-alarm`, 1 when an alarm
//! was raised; 1 when the filter could not be started; 2 on bad input.

use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;

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
    let report = match monitor(&input, &MonitorOptions::default()) {
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
            "{}: {} updates fused, {} rejected, {} skipped; final estimate moved {:.3} deg, {:.1} mm from the calibration of record",
            s.name,
            s.accepted,
            s.rejected,
            s.skipped.len(),
            s.rotation_change_deg,
            s.translation_change_m * 1e3
        );
    }
    for w in r.unobservable_words() {
        println!("{w}");
    }
}
