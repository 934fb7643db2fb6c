//! `msreg simulate lidar-imu` and `msreg calibrate lidar-imu` (the binary maps the outcome
//! to exit codes: errors are bad input, 2; not converged, 1).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;
use indicatif::ProgressBar;

use super::outcome::{progress_bar, Outcome};
use msreg_host::calibrate::driver::report::SectionFrame;
use msreg_host::calibrate::lidar_imu::{
    self, LidarImuCalibration, LidarImuInput, LidarImuOptions, LidarImuReport,
};
use msreg_host::calibrate::InputError;
use msreg_host::dataset::{
    list_scans, CalibrationResult, Dataset, SectionName, SensorId, SensorKind,
};
use msreg_host::lidar::FileScans;
use msreg_host::sim::{simulate_lidar_rig, Environment, LidarImuSimConfig, LidarSimConfig};

/// `msreg simulate lidar-imu`.
#[derive(Debug, Args)]
pub struct SimulateLidarImu {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Recording length, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Beams (128, 64, 32, 16); 128 x 1024 writes ~2.9 MB per scan (1.7 GB per minute).
    #[arg(long, default_value_t = 64)]
    pub rings: usize,
    /// Firings per sweep (1024, 512).
    #[arg(long, default_value_t = 512)]
    pub columns: usize,
    /// Time offset of the LiDAR, ms (stamp + offset = IMU time).
    #[arg(long, default_value_t = 0.0)]
    pub time_offset_ms: f64,
    /// 1-sigma range noise, m.
    #[arg(long, default_value_t = 0.02)]
    pub range_noise: f64,
    /// Sparser outdoor-like scene instead of the indoor room.
    #[arg(long)]
    pub outdoor: bool,
    /// LiDARs on the rig (1 to 4): lidar1.. get their own mounting, a time offset 4 ms * N
    /// below lidar0's and their own noise (docs/lidar_imu.md, "Several LiDARs").
    #[arg(long, default_value_t = 1)]
    pub lidars: usize,
}

/// `msreg calibrate lidar-imu`.
#[derive(Debug, Args)]
pub struct CalibrateLidarImu {
    /// Dataset directory (imu0/, lidar0/ and any further lidarN/: each is calibrated
    /// against imu0).
    pub dataset: PathBuf,
    /// Result YAML.
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (convergence history, sigmas, NDT fitness per scan, timing per stage).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Match raw scans (no motion compensation), for the dissertation's Fig. 3.11.
    #[arg(long)]
    pub no_deskew: bool,
    /// Keep the time offset fixed at zero.
    #[arg(long)]
    pub no_time_offset: bool,
    /// PNG plot of the extrinsic convergence (6 DoF and time offset, +-1 sigma bands).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Match each scan against a sliding map of this many recent deskewed scans instead of
    /// the previous scan (0 = scan-to-scan).
    #[arg(long, default_value_t = 5)]
    pub local_map_scans: usize,
}

fn bar(template: &str) -> ProgressBar {
    progress_bar(1000, template)
}

/// Simulates and writes a LiDAR-IMU dataset.
pub fn simulate(args: &SimulateLidarImu) -> anyhow::Result<()> {
    let config = LidarImuSimConfig {
        seed: args.seed,
        duration_s: args.duration,
        lidar: LidarSimConfig {
            rings: args.rings,
            columns: args.columns,
            time_offset_s: args.time_offset_ms * 1e-3,
            range_noise_m: args.range_noise,
            environment: if args.outdoor {
                Environment::Outdoor
            } else {
                Environment::Indoor
            },
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    };
    let rig = simulate_lidar_rig(&config, args.lidars).map_err(|e| anyhow!("simulate: {e}"))?;
    let sim = &rig.lidars[0];
    let progress = bar("{spinner} writing scans [{bar:40}] {percent}% {elapsed}");
    let mut show = |f: f64| progress.set_position((f * 1000.0) as u64);
    if args.lidars == 1 {
        sim.write(&args.out_dir, &mut show)?;
    } else {
        rig.write(&args.out_dir, &mut show)?;
    }
    progress.finish_and_clear();
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {} LiDAR(s), {} scans each of {} x {})",
        args.out_dir.display(),
        sim.imu.len(),
        args.lidars,
        sim.scan_stamps.len(),
        args.rings,
        args.columns
    );
    Ok(())
}

/// Calibrates every `lidarN/` of a dataset against `imu0/`, each with its own filter run;
/// writes one result with a `lidarN` section each, and the report (the one LiDAR's, or one
/// per LiDAR under its section name) and plots (`conv.png`, `conv.lidar1.png`, ...).
pub fn calibrate(args: &CalibrateLidarImu) -> anyhow::Result<Outcome> {
    let dataset = Dataset::open(&args.dataset)?;
    let mut lidars = dataset.sensors_of(SensorKind::Lidar)?;
    if lidars.is_empty() {
        // Not one LiDAR folder: the error names lidar0/.
        dataset.lidar0_scans()?;
        lidars.push(SensorId::lidar(0));
    }
    let mut result = CalibrationResult::new();
    let mut reports = BTreeMap::new();
    let (mut converged, mut reasons) = (true, Vec::new());
    for &lidar in &lidars {
        let calibration = calibrate_one(args, &dataset, lidar)?;
        let section = SectionName::Sensor(lidar);
        result = result.with_extrinsic(section, calibration.imu_sensor_estimate());
        result
            .section_mut(section)
            .hold_all(calibration.report.filter.held_dofs(SectionFrame::ImuSensor));
        plot(args, lidar, &calibration);
        let r = &calibration.report;
        converged &= r.filter.converged;
        reasons.extend(r.filter.reasons.iter().map(|why| format!("{lidar}: {why}")));
        summarise(lidar, r);
        reports.insert(lidar.to_string(), calibration.report);
    }
    match (reports.len(), reports.values().next()) {
        (1, Some(report)) => {
            super::outcome::write_outputs(&result, &args.output, args.report.as_deref(), report)?
        }
        _ => {
            super::outcome::write_outputs(&result, &args.output, args.report.as_deref(), &reports)?
        }
    }
    eprintln!("msreg: wrote {}", args.output.display());
    Ok(Outcome::of(converged, &reasons))
}

/// The LiDAR-IMU calibration of `lidar` against imu0.
fn calibrate_one(
    args: &CalibrateLidarImu,
    dataset: &Dataset,
    lidar: SensorId,
) -> anyhow::Result<LidarImuCalibration> {
    let scans = FileScans {
        files: list_scans(&dataset.path(&lidar.to_string()))?,
    };
    let input = LidarImuInput {
        imu: dataset.require_imu()?,
        imu_noise: dataset.require_imu_noise()?,
        scans: &scans,
    };
    let mut options = LidarImuOptions {
        deskew: !args.no_deskew,
        ..LidarImuOptions::for_local_map(args.local_map_scans)
    };
    options.filter.estimate_time_offset = !args.no_time_offset;
    let template = format!("{{spinner}} calibrating {lidar} [{{bar:40}}] {{percent}}% {{elapsed}}");
    let progress = bar(&template);
    let outcome = lidar_imu::calibrate::<f64>(&input, &options, &mut |f| {
        progress.set_position((f * 1000.0) as u64);
    });
    progress.finish_and_clear();
    outcome.map_err(|e: InputError| anyhow!("{}: {lidar}: {e}", args.dataset.display()))
}

/// `--plot`: lidar0's at the given path, lidarN's beside it as `<stem>.lidarN.<ext>`.
fn plot(args: &CalibrateLidarImu, lidar: SensorId, calibration: &LidarImuCalibration) {
    let Some(path) = &args.plot else {
        return;
    };
    let path = if lidar.index == 0 {
        path.clone()
    } else {
        let stem = path.file_stem().unwrap_or_default().to_string_lossy();
        let ext = path.extension().unwrap_or_default().to_string_lossy();
        path.with_file_name(format!("{stem}.{lidar}.{ext}"))
    };
    let series = msreg_host::calibrate::convergence::extrinsic_series(
        &calibration.report.filter.history,
        None,
    );
    let title = format!("T_imu_{lidar} convergence: {}", args.dataset.display());
    match msreg_host::plot::write_convergence_png(&path, &title, &series, (1500, 1100)) {
        Ok(()) => eprintln!("msreg: wrote {}", path.display()),
        // The calibration itself succeeded: a missing font is not bad input.
        Err(e) => eprintln!("msreg: warning: {e}"),
    }
}

/// One line per LiDAR: scans matched, settled NIS, NDT covariance scale, time.
fn summarise(lidar: SensorId, r: &LidarImuReport) {
    let settled = if r.settled_nis_per_dof.is_finite() {
        format!("{:.2}", r.settled_nis_per_dof)
    } else {
        "n/a (recording shorter than the noise annealing)".into()
    };
    eprintln!(
        "msreg: {lidar}: {} of {} scans matched, settled NIS/dof {settled}, NDT covariance \
         scale {:.3}, {:.1} s",
        r.scans_matched,
        r.scans_total,
        r.final_covariance_scale,
        r.stage_timing_s.rotation_init + r.stage_timing_s.total_filter_pass
    );
}
