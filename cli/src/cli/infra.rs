//! Command-line side of `msreg simulate infra` and `msreg calibrate infra`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use msreg_host::infra::sim::{simulate as run_sim, InfraSimConfig};

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
    /// Render images (each camera's frames of the marker, F's keyframes with the lights)
    /// instead of writing the detections as CSV: `calibrate infra` then detects them.
    #[arg(long)]
    pub images: bool,
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
    if args.images {
        eprintln!("msreg: rendering the marker and keyframe images ...");
        sim.write_with_images(&args.out_dir, args.seed)
    } else {
        sim.write(&args.out_dir)
    }
    .with_context(|| format!("writing {}", args.out_dir.display()))?;
    let n_det: usize = sim.detections.iter().map(Vec::len).sum();
    let n_obs: usize = sim.vo.images.iter().map(|i| i.keypoints.len()).sum();
    eprintln!(
        "msreg: wrote {} ({} cameras, {} marker {}, {} blob{}, {} keyframes, {} points, {} observations, VO drift {:.2} % of distance)",
        args.out_dir.display(),
        sim.cameras.len(),
        n_det,
        if args.images { "frames" } else { "detections" },
        sim.blobs.len(),
        if args.images { "s drawn" } else { "s" },
        sim.vo.images.len(),
        sim.vo.points.len(),
        n_obs,
        100.0 * sim.vo_drift_fraction
    );
    Ok(())
}

/// `msreg calibrate infra`.
#[derive(Args, Debug)]
pub struct CalibrateInfra {
    /// Dataset directory (cam0/, vo/, marker.yaml, infra/).
    pub dataset: PathBuf,
    /// Result YAML (`infra:` key).
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (per-camera RMSE and status, Sampson distances per pair, scale and
    /// T_F_M degeneracy).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// Runs `msreg calibrate infra`; `Ok(false)` when some camera could not be solved (the
/// result holds the others).
pub fn calibrate(args: &CalibrateInfra) -> anyhow::Result<bool> {
    let data = msreg_host::infra::dataset::InfraDataset::open(&args.dataset)?;
    let mut cal = msreg_host::infra::pipeline::calibrate(&data)
        .with_context(|| format!("{}", args.dataset.display()))?;
    let result_yaml = cal.result.to_yaml_string();
    cal.result.write(&args.output)?;
    if let Some(path) = &args.report {
        // A simulated dataset's truth goes into the top view (aligned onto the estimate).
        let truth = args.dataset.join("groundtruth/infra.yaml");
        if truth.is_file() {
            let truth = msreg_host::infra::io::InfraResultFile::read(&truth)?;
            cal.report.top_view.add_truth(&truth)?;
        }
        msreg_host::report::write_report_for_result(
            path,
            &cal.report,
            (&args.output, &result_yaml),
            &[],
            &[],
        )?;
    }
    let failed: Vec<&msreg_host::infra::pipeline::CameraReport> =
        cal.report.cameras.iter().filter(|c| !c.solved).collect();
    for c in &failed {
        eprintln!(
            "msreg: camera {} not solved: {}",
            c.id,
            c.reason.as_deref().unwrap_or("unknown")
        );
    }
    if let Some(m) = &cal.report.motion {
        if !m.degeneracy.is_empty() {
            eprintln!("msreg: T_cam0_marker from motion is degenerate in {} direction(s) (planar driving); see the report", m.degeneracy.len());
        }
    }
    eprintln!(
        "msreg: wrote {} ({} of {} cameras solved, VO scale {:.6} m/unit)",
        args.output.display(),
        cal.result.infra.cameras.len(),
        data.cameras.len(),
        cal.result.infra.vo_scale
    );
    Ok(failed.is_empty())
}
