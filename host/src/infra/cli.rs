//! Command-line side of `msreg simulate infra` and `msreg calibrate infra`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use super::sim::{simulate as run_sim, InfraSimConfig};

/// `msreg simulate infra`.
#[derive(Args, Debug)]
pub struct SimulateInfra {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Seed of the run (robot, VO, detections).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Seed of the building (camera placement, ceiling); defaults to --seed. Two runs with
    /// the same building seed and different seeds are a repeatability pair.
    #[arg(long)]
    pub building_seed: Option<u64>,
    /// Number of infrastructure cameras.
    #[arg(long, default_value_t = 40)]
    pub cameras: usize,
}

/// Runs `msreg simulate infra`.
pub fn simulate(args: &SimulateInfra) -> anyhow::Result<()> {
    let mut config = InfraSimConfig {
        seed: args.seed,
        building_seed: args.building_seed.unwrap_or(args.seed),
        ..InfraSimConfig::default()
    };
    config.scene.cameras = args.cameras;
    let sim = run_sim(&config);
    sim.write(&args.out_dir)
        .with_context(|| format!("writing {}", args.out_dir.display()))?;
    let n_det: usize = sim.detections.iter().map(Vec::len).sum();
    let n_obs: usize = sim.vo.images.iter().map(|i| i.keypoints.len()).sum();
    eprintln!(
        "msreg: wrote {} ({} cameras, {} marker detections, {} blobs, {} keyframes, {} points, {} observations, VO drift {:.2} % of distance)",
        args.out_dir.display(),
        sim.cameras.len(),
        n_det,
        sim.blobs.len(),
        sim.vo.images.len(),
        sim.vo.points.len(),
        n_obs,
        100.0 * sim.vo_drift_fraction
    );
    Ok(())
}
