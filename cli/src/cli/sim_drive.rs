//! `msreg simulate drive`: the command-line face of [`msreg_host::sim::drive_sim`].

use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;

use msreg_host::sim::drive_sim::{simulate_drive, DriveSimConfig, KnockTarget};

/// `--knock-sensor`: `none` or `poseK`.
fn knock_sensor(text: &str) -> Result<KnockTarget, String> {
    if text == "none" {
        return Ok(KnockTarget::None);
    }
    text.strip_prefix("pose")
        .and_then(|k| k.parse::<usize>().ok())
        .map(|k| match k {
            0 => KnockTarget::Pose0,
            1 => KnockTarget::Pose1,
            k => KnockTarget::Pose(k),
        })
        .ok_or_else(|| format!("`{text}`: expected `none` or `poseK` (pose0, pose1, ...)"))
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
    /// Knocked sensor: `pose0` (the LiDAR), `pose1` (the camera), `poseK`, or `none`.
    #[arg(long, value_parser = knock_sensor, default_value = "pose1")]
    pub knock_sensor: KnockTarget,
    /// Number of pose sensors: pose0 (LiDAR odometry), pose1 (camera VO), pose2, ... (further
    /// LiDAR odometries), each with its own mounting, time offset and noise.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..))]
    pub pose_sensors: u16,
}

/// The simulator options of the arguments.
pub fn config_of(args: &SimulateDrive) -> DriveSimConfig {
    DriveSimConfig {
        seed: args.seed,
        duration_s: args.duration,
        knock_at_s: args.knock_s,
        knock_deg: args.knock_deg,
        knock_target: args.knock_sensor,
        pose_sensors: usize::from(args.pose_sensors),
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
    let poses: Vec<String> = sim
        .sensors
        .iter()
        .enumerate()
        .map(|(k, s)| format!("{} pose{k} poses", s.poses.len()))
        .collect();
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {}; {knock})",
        args.out_dir.display(),
        sim.imu.len(),
        poses.join(", "),
    );
    Ok(())
}
