//! `msreg simulate drive`: the command-line face of [`msreg_host::sim::drive_sim`].

use std::path::PathBuf;

use anyhow::anyhow;
use clap::{Args, ValueEnum};

use msreg_host::sim::drive_sim::{simulate_drive, DriveSimConfig, KnockTarget};

/// Which sensor the knock hits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KnockSensorArg {
    /// The camera's visual odometry.
    Pose1,
    /// The LiDAR odometry.
    Pose0,
    /// No knock.
    None,
}

/// `msreg simulate drive`.
#[derive(Debug, Args)]
pub struct SimulateDrive {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Recording length, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Knock time, s after the start.
    #[arg(long, default_value_t = 30.0)]
    pub knock_s: f64,
    /// Knock angle, deg.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    pub knock_deg: f64,
    /// Knocked sensor.
    #[arg(long, value_enum, default_value_t = KnockSensorArg::Pose1)]
    pub knock_sensor: KnockSensorArg,
}

/// The simulator options of the arguments.
pub fn config_of(args: &SimulateDrive) -> DriveSimConfig {
    DriveSimConfig {
        seed: args.seed,
        duration_s: args.duration,
        knock_at_s: args.knock_s,
        knock_deg: args.knock_deg,
        knock_target: match args.knock_sensor {
            KnockSensorArg::Pose0 => KnockTarget::Pose0,
            KnockSensorArg::Pose1 => KnockTarget::Pose1,
            KnockSensorArg::None => KnockTarget::None,
        },
        ..DriveSimConfig::default()
    }
}

/// Simulates and writes the dataset.
pub fn simulate(args: &SimulateDrive) -> anyhow::Result<()> {
    let sim = simulate_drive(&config_of(args)).map_err(|e| anyhow!("simulate: {e}"))?;
    sim.write(&args.out_dir)?;
    let knock = match sim.knock() {
        Some((name, at)) => format!("{name} knocked by {} deg at {at} s", args.knock_deg),
        None => "no knock".into(),
    };
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {} LiDAR odometry poses, {} VO poses; {knock})",
        args.out_dir.display(),
        sim.imu.len(),
        sim.sensors[0].poses.len(),
        sim.sensors[1].poses.len(),
    );
    Ok(())
}
