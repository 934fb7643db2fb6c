//! `msreg simulate camera-imu`: the command-line face of [`msreg_host::sim::camera`].

use std::path::PathBuf;
use std::time::Instant;

use super::outcome::progress_bar;
use anyhow::anyhow;
use clap::{Args, ValueEnum};

use msreg_host::calibrate::camera_imu::MAX_CAMERAS;
use msreg_host::sim::camera::rig::{simulate_camera_rig, CameraRigSimConfig};
use msreg_host::sim::camera::{simulate_camera_imu, CameraImuSimConfig, CameraModelChoice};

/// The `--model` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// EuRoC cam0 (752 x 480, pinhole + radtan).
    PinholeRadtan,
    /// Wide-angle 752 x 480, pinhole + equidistant.
    PinholeEquidistant,
}

/// `msreg simulate camera-imu`.
#[derive(Debug, Args)]
pub struct SimulateCameraImu {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Recording length, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Camera frame rate, Hz.
    #[arg(long, default_value_t = 20.0)]
    pub rate_hz: f64,
    /// Motion blur: 4 ms exposure, the image integrated over the motion.
    #[arg(long)]
    pub blur: bool,
    /// Gaussian noise (sigma 2.5 grey levels) and a lighting gradient across the image.
    #[arg(long)]
    pub noise: bool,
    /// Time offset of the camera, ms (stamp + offset = IMU time).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub time_offset_ms: f64,
    /// Camera model.
    #[arg(long, value_enum, default_value_t = ModelArg::PinholeRadtan)]
    pub model: ModelArg,
    /// Print a Kalibr AprilGrid (6 x 5 tag36h11 tags of 5 cm, spacing 0.3) instead of the
    /// checkerboard: images, target.yaml and ground-truth corners in Kalibr's ids.
    #[arg(long)]
    pub aprilgrid: bool,
    /// Cameras on the rig (1-4): camera n sits 11 cm along camera 0's x axis from camera
    /// n-1, turned 4 deg towards the row's start, its time offset 3 ms after camera n-1's
    /// (`cam0/` .. `camN-1/`, every `camN` in the ground truth with `T_cn_cnm1`).
    #[arg(long, default_value_t = 1)]
    pub cameras: usize,
}

/// Simulates and writes the dataset, with a progress bar on stderr.
pub fn simulate(args: &SimulateCameraImu) -> anyhow::Result<()> {
    let mut config = CameraImuSimConfig {
        seed: args.seed,
        duration_s: args.duration,
        rate_hz: args.rate_hz,
        time_offset_s: args.time_offset_ms * 1e-3,
        camera: match args.model {
            ModelArg::PinholeRadtan => CameraModelChoice::PinholeRadtan,
            ModelArg::PinholeEquidistant => CameraModelChoice::PinholeEquidistant,
        }
        .camera(),
        aprilgrid: args.aprilgrid.then(CameraImuSimConfig::default_aprilgrid),
        ..CameraImuSimConfig::default()
    };
    let realistic = CameraImuSimConfig::default().with_blur_and_noise();
    if args.blur {
        config.exposure_s = realistic.exposure_s;
    }
    if args.noise {
        config.noise_sigma = realistic.noise_sigma;
        config.lighting_gradient = realistic.lighting_gradient;
    }
    if !(1..=MAX_CAMERAS).contains(&args.cameras) {
        return Err(anyhow!(
            "--cameras must be 1 to {MAX_CAMERAS}, got {}",
            args.cameras
        ));
    }
    if args.cameras > 1 {
        return simulate_rig(args, config);
    }
    let started = Instant::now();
    let sim = simulate_camera_imu(&config).map_err(|e| anyhow!("simulate: {e}"))?;
    let bar = progress_bar(
        1000,
        "{spinner} rendering images [{bar:40}] {percent}% {elapsed}",
    );
    sim.write(&args.out_dir, &|f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {} images, {:.1} s)",
        args.out_dir.display(),
        sim.imu.len(),
        sim.frame_stamps.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `--cameras N` with N > 1: the row of cameras of [`CameraRigSimConfig::row`].
fn simulate_rig(args: &SimulateCameraImu, config: CameraImuSimConfig) -> anyhow::Result<()> {
    let started = Instant::now();
    let rig = simulate_camera_rig(&CameraRigSimConfig::row(config, args.cameras))
        .map_err(|e| anyhow!("simulate: {e}"))?;
    let bar = progress_bar(
        1000,
        "{spinner} rendering images [{bar:40}] {percent}% {elapsed}",
    );
    rig.write(&args.out_dir, &|f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {} cameras, {} images, {:.1} s)",
        args.out_dir.display(),
        rig.cameras[0].imu.len(),
        rig.cameras.len(),
        rig.cameras
            .iter()
            .map(|c| c.frame_stamps.len())
            .sum::<usize>(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
