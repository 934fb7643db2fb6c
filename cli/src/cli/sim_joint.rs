//! `msreg simulate joint`: the command-line face of [`msreg_host::sim::joint`].

use std::path::PathBuf;
use std::time::Instant;

use anyhow::anyhow;
use clap::Args;

use super::outcome::progress_bar;
use msreg_host::sim::joint::{simulate_joint, JointSimConfig};

/// `msreg simulate joint`.
#[derive(Debug, Args)]
pub struct SimulateJoint {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Recording length, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Time offset of the camera, ms (stamp + offset = IMU time).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub camera_time_offset_ms: f64,
    /// Time offset of the LiDAR, ms (stamp + offset = IMU time).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub lidar_time_offset_ms: f64,
    /// LiDAR beams.
    #[arg(long, default_value_t = 64)]
    pub rings: usize,
    /// LiDAR firings per sweep.
    #[arg(long, default_value_t = 1024)]
    pub columns: usize,
}

/// Simulates and writes the dataset, with a progress bar on stderr.
pub fn simulate(args: &SimulateJoint) -> anyhow::Result<()> {
    let mut config = JointSimConfig::default();
    config.camera.seed = args.seed;
    config.camera.duration_s = args.duration;
    config.camera.time_offset_s = args.camera_time_offset_ms * 1e-3;
    config.lidar.time_offset_s = args.lidar_time_offset_ms * 1e-3;
    config.lidar.rings = args.rings;
    config.lidar.columns = args.columns;
    let started = Instant::now();
    let sim = simulate_joint(&config).map_err(|e| anyhow!("simulate: {e}"))?;
    let bar = progress_bar(
        1000,
        "{spinner} rendering images and casting scans [{bar:40}] {percent}% {elapsed}",
    );
    sim.write(&args.out_dir, &|f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {} images, {} scans, {:.1} s)",
        args.out_dir.display(),
        sim.camera.imu.len(),
        sim.camera.frame_stamps.len(),
        sim.lidar.scan_stamps.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
