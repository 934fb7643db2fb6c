//! `msreg simulate cameras`: the command-line face of [`msreg_host::sim::cameras`].

use std::path::PathBuf;
use std::time::Instant;

use super::outcome::progress_bar;
use anyhow::anyhow;
use clap::{Args, ValueEnum};

use msreg_host::sim::cameras::models::ModelKind;
use msreg_host::sim::cameras::{simulate_cameras, CamerasSimConfig, SimTarget};
use msreg_host::sim::CameraImuSimConfig;

/// The `--model` values (Kalibr's models).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CameraModelArg {
    /// Pinhole + radial-tangential (EuRoC cam0-like, 752 x 480).
    PinholeRadtan,
    /// Pinhole + equidistant (Kannala-Brandt), a wide-angle lens.
    PinholeEquidistant,
    /// Mei's unified model + radial-tangential.
    OmniRadtan,
    /// Double Sphere.
    Ds,
    /// Enhanced Unified Camera Model.
    Eucm,
}

/// The `--target` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TargetArg {
    /// 6 x 7 inner corners at 6 cm.
    Checkerboard,
    /// 6 x 5 tag36h11 tags of 5 cm, spacing 0.3.
    Aprilgrid,
}

/// `msreg simulate cameras`.
#[derive(Debug, Args)]
pub struct SimulateCameras {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Number of cameras on the rig (a stereo pair by default).
    #[arg(long, default_value_t = 2)]
    pub cameras: usize,
    /// Lens model of every camera.
    #[arg(long, value_enum, default_value_t = CameraModelArg::PinholeRadtan)]
    pub model: CameraModelArg,
    /// The printed target.
    #[arg(long, value_enum, default_value_t = TargetArg::Checkerboard)]
    pub target: TargetArg,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Images per camera.
    #[arg(long, default_value_t = 100)]
    pub frames: usize,
    /// Frame rate, Hz.
    #[arg(long, default_value_t = 10.0)]
    pub rate_hz: f64,
    /// camN is triggered N x this many ms after cam0 (stamps differ); 0: shared stamps.
    #[arg(long, default_value_t = 0.0)]
    pub unsynced_ms: f64,
    /// Motion blur: 4 ms exposure.
    #[arg(long)]
    pub blur: bool,
    /// Gaussian noise (2.5 grey levels) and a lighting gradient.
    #[arg(long)]
    pub noise: bool,
}

/// Simulates and writes the dataset, with a progress bar on stderr.
pub fn simulate(args: &SimulateCameras) -> anyhow::Result<()> {
    let mut config = CamerasSimConfig {
        seed: args.seed,
        cameras: args.cameras,
        model: match args.model {
            CameraModelArg::PinholeRadtan => ModelKind::PinholeRadtan,
            CameraModelArg::PinholeEquidistant => ModelKind::PinholeEquidistant,
            CameraModelArg::OmniRadtan => ModelKind::OmniRadtan,
            CameraModelArg::Ds => ModelKind::DoubleSphere,
            CameraModelArg::Eucm => ModelKind::Eucm,
        },
        target: match args.target {
            TargetArg::Checkerboard => SimTarget::Checkerboard(CameraImuSimConfig::default().board),
            TargetArg::Aprilgrid => CamerasSimConfig::default_aprilgrid(),
        },
        frames: args.frames,
        rate_hz: args.rate_hz,
        unsynced_s: args.unsynced_ms * 1e-3,
        ..CamerasSimConfig::default()
    };
    let realistic = CamerasSimConfig::default().with_blur_and_noise();
    if args.blur {
        config.exposure_s = realistic.exposure_s;
    }
    if args.noise {
        config.noise_sigma = realistic.noise_sigma;
        config.lighting_gradient = realistic.lighting_gradient;
    }
    let started = Instant::now();
    let sim = simulate_cameras(&config).map_err(|e| anyhow!("simulate: {e}"))?;
    let bar = progress_bar(
        1000,
        "{spinner} rendering images [{bar:40}] {percent}% {elapsed}",
    );
    sim.write(&args.out_dir, &|f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    eprintln!(
        "msreg: wrote {} ({} camera(s) x {} images, {:.1} s)",
        args.out_dir.display(),
        config.cameras,
        config.frames,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
