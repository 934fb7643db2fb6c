//! `msreg calibrate prior-map <dataset>`: reads the dataset, initialises (user
//! correspondences or automatic matching), runs the MI stage and writes the result
//! (`cam0.T_world_cam` with sigmas, MI / NMI, plus a `cam0_mi` section with observability),
//! overlays before (initial pose) and after, and an optional JSON / HTML report with the
//! survey-point reprojection errors.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use nalgebra::Isometry3;
use serde::Serialize;

use super::mi::{dof_table, mi_section, outcome_of, write_overlay, RefinedSummary};
use super::outcome::Outcome;
use msreg_host::dataset::ExtrinsicEstimate;
use msreg_host::mi::prior_map::init::{InitError, Initialisation};
use msreg_host::mi::prior_map::input::{read_input, PriorMapInput};
use msreg_host::mi::prior_map::{
    median, register, survey_errors, t_world_cam_yaml, RegisterError, RegisterOptions,
};

/// `msreg calibrate prior-map`.
#[derive(Debug, Args)]
pub struct CalibratePriorMap {
    /// Dataset directory (map/, cam0/, prior.yaml, optional survey.csv).
    pub dataset: PathBuf,
    /// Result YAML.
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// Report: JSON (`*.json`) or a self-contained HTML page (`*.html`).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Overlay PNG after the MI stage (default: the output with extension png; the
    /// overlay of the initial pose is written beside it as `<stem>_initial.png`).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
}

/// Errors against `groundtruth/extrinsics.yaml` when present.
#[derive(Serialize)]
struct TruthErrors {
    position_m: [f64; 3],
    rotation_deg: [f64; 3],
    yaw_deg: f64,
}

#[derive(Serialize)]
struct Report {
    dataset: String,
    image: String,
    init: Initialisation,
    points_used: usize,
    grid_evaluations: usize,
    #[serde(flatten)]
    refined: RefinedSummary,
    survey_px_initial: Vec<f64>,
    survey_px: Vec<f64>,
    survey_median_px_initial: f64,
    survey_median_px: f64,
    t_world_cam_initial: [[f64; 4]; 4],
    t_world_cam: [[f64; 4]; 4],
    truth_errors: Option<TruthErrors>,
    /// MI along each DoF through the optimum, with the refinement's parabola.
    mi_slices: Vec<msreg_host::mi::prior_map::slices::MiSlice>,
    seconds: f64,
}

fn rows(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

fn truth_errors(dataset: &Path, estimate: &Isometry3<f64>) -> Option<TruthErrors> {
    let truth =
        msreg_host::dataset::read_t_world_cam(&dataset.join("groundtruth/extrinsics.yaml")).ok()?;
    let dp = estimate.translation.vector - truth.translation.vector;
    let dr = (truth.rotation.inverse() * estimate.rotation).scaled_axis();
    Some(TruthErrors {
        position_m: dp.into(),
        rotation_deg: dr.map(f64::to_degrees).into(),
        yaw_deg: msreg_host::mi::prior_map::yaw_error(estimate, &truth).to_degrees(),
    })
}

/// Writes the result file of a failed initialisation (no pose) and says why.
fn write_failure(output: &Path, why: &str) -> anyhow::Result<Outcome> {
    std::fs::write(
        output,
        format!("# msreg calibrate prior-map: no pose\ncam0_prior_map:\n  status: failed\n  reason: {why:?}\n"),
    )
    .with_context(|| format!("{}: cannot write", output.display()))?;
    Ok(Outcome::NotConverged(why.to_string()))
}

/// Runs the command; `Err` is bad input (exit code 2).
pub fn calibrate(args: &CalibratePriorMap) -> anyhow::Result<Outcome> {
    let input = read_input(&args.dataset)?;
    let clock = std::time::Instant::now();
    let reg = match register(&input, &RegisterOptions::default()) {
        Ok(r) => r,
        Err(RegisterError::Init(InitError::Pnp(e))) => {
            anyhow::bail!("{}: {e}", args.dataset.join("prior.yaml").display())
        }
        Err(RegisterError::Init(e @ (InitError::NoPrior | InitError::NoSatellite))) => {
            anyhow::bail!("{}: {e}", args.dataset.display())
        }
        Err(e) => return write_failure(&args.output, &e.to_string()),
    };
    let seconds = clock.elapsed().as_secs_f64();
    let r = &reg.refined;
    let estimate = ExtrinsicEstimate::from_covariance(r.x, 0.0, &r.covariance);
    let mut text = t_world_cam_yaml(
        &r.x,
        estimate.sigma_rot_deg.into(),
        estimate.sigma_trans_m.into(),
    );
    text.push_str(&format!(
        "  mi: {}\n  nmi: {}\n",
        r.smoothed.mi, r.smoothed.nmi
    ));
    let held: Vec<&str> = super::mi::held_dofs(r).iter().map(|d| d.as_str()).collect();
    if !held.is_empty() {
        text.push_str(&format!(
            "  held: [{}]  # at their prior: not determined by the data\n",
            held.join(", ")
        ));
    }
    text.push_str(&mi_section("cam0_mi", r));
    std::fs::write(&args.output, &text)
        .with_context(|| format!("{}: cannot write", args.output.display()))?;
    let overlay = args
        .overlay
        .clone()
        .unwrap_or_else(|| args.output.with_extension("png"));
    let stem = overlay
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("overlay");
    let before = overlay.with_file_name(format!("{stem}_initial.png"));
    write_overlay(
        &overlay,
        &input.image,
        &input.map,
        &input.camera,
        &r.x.inverse(),
    )?;
    write_overlay(
        &before,
        &input.image,
        &input.map,
        &input.camera,
        &reg.init.t_world_cam.inverse(),
    )?;
    let report = make_report(args, &input, &reg, seconds);
    eprintln!(
        "msreg: wrote {} (init {:?}: {} inliers of {} matches; MI {:.4}, NMI {:.4}; survey median \
         {:.2} px (initial {:.2} px); {:.1} s)",
        args.output.display(),
        reg.init.source,
        reg.init.inliers,
        reg.init.matches,
        r.smoothed.mi,
        r.smoothed.nmi,
        report.survey_median_px,
        report.survey_median_px_initial,
        seconds
    );
    eprint!("{}", dof_table(r));
    if let Some(path) = &args.report {
        msreg_host::report::write_report_for_result(
            path,
            &report,
            (&args.output, &text),
            &[before, overlay],
            &[],
        )?;
    }
    Ok(outcome_of(r))
}

fn make_report(
    args: &CalibratePriorMap,
    input: &PriorMapInput,
    reg: &msreg_host::mi::prior_map::Registration,
    seconds: f64,
) -> Report {
    let r = &reg.refined;
    let initial = survey_errors(&input.camera, &reg.init.t_world_cam, &input.survey);
    let after = survey_errors(&input.camera, &r.x, &input.survey);
    Report {
        dataset: args.dataset.display().to_string(),
        image: input.image_path.display().to_string(),
        init: reg.init.clone(),
        points_used: reg.points_used,
        grid_evaluations: reg.grid_evaluations,
        refined: RefinedSummary::of(r),
        survey_median_px_initial: median(&initial),
        survey_median_px: median(&after),
        survey_px_initial: initial,
        survey_px: after,
        t_world_cam_initial: rows(&reg.init.t_world_cam),
        t_world_cam: rows(&r.x),
        truth_errors: truth_errors(&args.dataset, &r.x),
        mi_slices: reg.slices.clone(),
        seconds,
    }
}
