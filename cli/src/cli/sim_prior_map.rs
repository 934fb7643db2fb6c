//! `msreg simulate prior-map`: the command-line face of [`msreg_host::sim::prior_map`].

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use msreg_host::sim::prior_map::{simulate_prior_map, FisheyeModel, PriorMapSimConfig};

/// The `--model` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FisheyeModelArg {
    /// Pinhole + equidistant (Kannala-Brandt) distortion.
    Equidistant,
    /// Mei's unified model (Kalibr omni) with radtan distortion.
    Omni,
}

/// `msreg simulate prior-map`.
#[derive(Debug, Args)]
pub struct SimulatePriorMap {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fisheye camera model.
    #[arg(long, value_enum, default_value_t = FisheyeModelArg::Equidistant)]
    pub model: FisheyeModelArg,
    /// Horizontal error of the GPS prior, m (default: random 2-5 m).
    #[arg(long)]
    pub prior_offset_m: Option<f64>,
    /// A small problem (400 px image, 20 m map, 40k points) for quick runs and CI.
    #[arg(long)]
    pub small: bool,
}

/// The simulator settings of the arguments.
pub fn config_of(args: &SimulatePriorMap) -> PriorMapSimConfig {
    let base = if args.small {
        PriorMapSimConfig::small(args.seed)
    } else {
        PriorMapSimConfig {
            seed: args.seed,
            ..PriorMapSimConfig::default()
        }
    };
    PriorMapSimConfig {
        model: match args.model {
            FisheyeModelArg::Equidistant => FisheyeModel::Equidistant,
            FisheyeModelArg::Omni => FisheyeModel::Omni,
        },
        prior_offset_m: args.prior_offset_m,
        ..base
    }
}

/// Simulates and writes the dataset.
pub fn simulate(args: &SimulatePriorMap) -> anyhow::Result<()> {
    let sim = simulate_prior_map(&config_of(args));
    sim.write(&args.out_dir)?;
    let p = sim.t_world_cam.translation.vector;
    eprintln!(
        "msreg: wrote {} ({} map points, {} x {} satellite, camera at ({:.2}, {:.2}, {:.2}) m, \
         prior {:.2} m off, {} survey points)",
        args.out_dir.display(),
        sim.map.len(),
        sim.satellite.width(),
        sim.satellite.height(),
        p.x,
        p.y,
        p.z,
        (sim.prior.position - p).xy().norm(),
        sim.survey.len()
    );
    Ok(())
}
