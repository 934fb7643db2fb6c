//! `msreg simulate imu-imu` and `msreg calibrate imu-imu`: every further IMU of a rig against
//! `imu0` ([`msreg_host::calibrate::imu_imu`]). Errors are bad input (exit 2); a rig whose
//! lever arm could not be determined on some axis is written with `held` and exits 1.

use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;
use serde::Serialize;

use super::outcome::Outcome;
use msreg_host::calibrate::imu_imu::{calibrate_rig, ImuImuOptions, ImuRigCalibration};
use msreg_host::dataset::Dataset;
use msreg_host::sim::{simulate_imus, ImusSimConfig};

/// `msreg simulate imu-imu`.
#[derive(Debug, Args)]
pub struct SimulateImuImu {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Number of IMUs, imu0 included (2-16); each further IMU gets its own mounting, rate
    /// (100-400 Hz), noise, biases and clock offset (+-50 ms).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(2..=16))]
    pub imus: u16,
    /// Recording length, s.
    #[arg(long, default_value_t = 20.0)]
    pub duration: f64,
}

/// `msreg calibrate imu-imu`.
#[derive(Debug, Args)]
pub struct CalibrateImuImu {
    /// Dataset directory (imu0/, imu1/, ...).
    pub dataset: PathBuf,
    /// Result YAML: an `imuN` section per further IMU.
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (per IMU: estimate, sigmas, bias differences, rotation excitation).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Largest clock offset searched between two IMUs, ms.
    #[arg(long, default_value_t = 200.0)]
    pub max_offset_ms: f64,
}

/// Simulates and writes an IMU-rig dataset.
pub fn simulate(args: &SimulateImuImu) -> anyhow::Result<()> {
    let config = ImusSimConfig {
        seed: args.seed,
        imus: usize::from(args.imus),
        duration_s: args.duration,
        ..ImusSimConfig::default()
    };
    let sim = simulate_imus(&config).map_err(|e| anyhow!("simulate: {e}"))?;
    sim.write(&args.out_dir)?;
    let counts: Vec<String> = sim
        .imus
        .iter()
        .enumerate()
        .map(|(n, imu)| format!("imu{n} {} samples", imu.records.len()))
        .collect();
    eprintln!(
        "msreg: wrote {} ({})",
        args.out_dir.display(),
        counts.join(", ")
    );
    Ok(())
}

/// One IMU's row of the JSON report.
#[derive(Debug, Serialize)]
struct PairRow {
    sensor: String,
    rotation_vector_rad: [f64; 3],
    translation_m: [f64; 3],
    timeshift_imu_imu0_s: f64,
    sigma_rotation_deg: [f64; 3],
    sigma_translation_m: [f64; 3],
    sigma_timeshift_s: f64,
    gyro_bias_difference_rad_s: [f64; 3],
    accel_bias_difference_m_s2: [f64; 3],
    rate_spread_rad_s: [f64; 3],
    held: Vec<String>,
}

fn rows(rig: &ImuRigCalibration) -> Vec<PairRow> {
    rig.pairs
        .iter()
        .map(|p| {
            let e = &p.estimate;
            PairRow {
                sensor: p.sensor.to_string(),
                rotation_vector_rad: e.rotation.scaled_axis().into(),
                translation_m: e.translation.into(),
                timeshift_imu_imu0_s: e.timeshift_s,
                sigma_rotation_deg: e.sigma_rotation.map(f64::to_degrees).into(),
                sigma_translation_m: e.sigma_translation.into(),
                sigma_timeshift_s: e.sigma_timeshift_s,
                gyro_bias_difference_rad_s: e.gyro_bias_diff.into(),
                accel_bias_difference_m_s2: e.accel_bias_diff.into(),
                rate_spread_rad_s: e.rate_spread.into(),
                held: p.held.iter().map(|d| d.as_str().to_string()).collect(),
            }
        })
        .collect()
}

/// Calibrates every `imuN` against `imu0`, writes the result (and the report) and prints a
/// line per IMU.
pub fn run(args: &CalibrateImuImu) -> anyhow::Result<Outcome> {
    let dataset = Dataset::open(&args.dataset)?;
    let options = ImuImuOptions {
        max_offset_s: args.max_offset_ms * 1e-3,
        ..ImuImuOptions::default()
    };
    let rig = calibrate_rig(&dataset, &options, |sensor| {
        eprintln!("msreg: calibrating {sensor} against imu0");
    })?;
    let result_yaml = rig.result.to_yaml_string();
    super::outcome::write_outputs(&rig.result, &args.output, None, &())?;
    let rows = rows(&rig);
    for row in &rows {
        println!(
            "{}: rotation {:.4} deg (sigma {:.4}), lever [{:.4}, {:.4}, {:.4}] m (sigma {:.4}), \
             timeshift_imu_imu0 {:.4} ms (sigma {:.4})",
            row.sensor,
            nalgebra::Vector3::from(row.rotation_vector_rad)
                .norm()
                .to_degrees(),
            nalgebra::Vector3::from(row.sigma_rotation_deg).norm(),
            row.translation_m[0],
            row.translation_m[1],
            row.translation_m[2],
            nalgebra::Vector3::from(row.sigma_translation_m).norm(),
            row.timeshift_imu_imu0_s * 1e3,
            row.sigma_timeshift_s * 1e3
        );
    }
    println!("msreg: wrote {}", args.output.display());
    if let Some(path) = &args.report {
        let report = serde_json::json!({ "imus": &rows });
        msreg_host::report::write_report_for_result(
            path,
            &report,
            (&args.output, &result_yaml),
            &[],
            &[],
        )?;
        println!("msreg: wrote {}", path.display());
    }
    let held: Vec<String> = rows
        .iter()
        .filter(|r| !r.held.is_empty())
        .map(|r| format!("{}: {} held at 0", r.sensor, r.held.join(", ")))
        .collect();
    Ok(Outcome::of(
        held.is_empty(),
        &[format!(
            "lever arm not determined by the recording (sigma above {} m; rotate about more \
         axes, docs/recording.md): {}",
            msreg_host::calibrate::imu_imu::LEVER_HELD_SIGMA_M,
            held.join("; ")
        )],
    ))
}
