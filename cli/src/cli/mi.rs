//! `msreg calibrate lidar-camera <dataset> --targetless --initial guess.yaml` (routed here
//! by `lidar_camera::cli` with [`TargetlessArgs`]): loads the
//! first image and the scan nearest to it, runs [`msreg_host::mi::targetless`], writes the result
//! (`cam0_lidar0` with sigmas, plus a `cam0_lidar0_mi` section), an optional JSON report
//! and overlays before / after.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Vector6};
use serde::Serialize;

use super::outcome::Outcome;
use msreg_host::camera_yaml::read_camera_yaml;
use msreg_host::dataset::{
    list_scans, read_camera_csv, CalibrationResult, Dof, ExtrinsicEstimate, SectionName,
    CAMERA_CSV, CAMERA_YAML,
};
use msreg_host::mi::scene::rank_normalize;
use msreg_host::mi::search::{default_prior_sigma, Constraint, Observability, Refined};
use msreg_host::mi::targetless::{calibrate_targetless, TargetlessOptions, TargetlessResult};
use msreg_host::pointcloud::{read_pcd, PointCloud};
use msreg_host::report::{write_result_and_report, RunOutputs};
use msreg_host::vision::GrayImage;

/// Names of the six DoF of `delta`.
pub const DOF_NAMES: [&str; 6] = ["rot_x", "rot_y", "rot_z", "x", "y", "z"];

/// JSON report of a targetless run.
#[derive(Serialize)]
struct Report {
    dataset: String,
    image: String,
    scan: String,
    points_used: usize,
    grid_evaluations: usize,
    mi_initial: f64,
    #[serde(flatten)]
    refined: RefinedSummary,
    t_cam_lidar: [[f64; 4]; 4],
    seconds: f64,
}

/// The report fields of a refinement: iterations, MI / NMI, sigmas, observability.
#[derive(Serialize)]
pub struct RefinedSummary {
    iterations: usize,
    converged: bool,
    mi: f64,
    nmi: f64,
    mi_hard: f64,
    nmi_hard: f64,
    n_eff: usize,
    sigma_rot_deg: [f64; 3],
    sigma_trans_m: [f64; 3],
    observability: Vec<(String, Observability)>,
    held: Vec<String>,
    /// Per DoF: `measured` (sigma from the MI curvature) or why it is not.
    constraint: Vec<(String, Constraint)>,
    /// The DoFs the MI does not constrain; their sigmas are `prior_sigma_*`.
    unconstrained: Vec<String>,
    prior_sigma_rot_deg: [f64; 3],
    prior_sigma_trans_m: [f64; 3],
}

impl RefinedSummary {
    /// The summary of `r` (sigmas from its covariance).
    pub fn of(r: &Refined) -> Self {
        let estimate = ExtrinsicEstimate::from_covariance(r.x, 0.0, &r.covariance);
        Self {
            iterations: r.iterations,
            converged: r.converged,
            mi: r.smoothed.mi,
            nmi: r.smoothed.nmi,
            mi_hard: r.hard.mi,
            nmi_hard: r.hard.nmi,
            n_eff: r.n_eff,
            sigma_rot_deg: estimate.sigma_rot_deg.into(),
            sigma_trans_m: estimate.sigma_trans_m.into(),
            observability: named(&r.observability),
            held: held_names(r),
            constraint: named(&r.constraint),
            unconstrained: unconstrained_names(r),
            prior_sigma_rot_deg: prior_rot_deg(r),
            prior_sigma_trans_m: prior_trans_m(r),
        }
    }
}

/// Each DoF's name with its value.
fn named<T: Copy>(values: &[T; 6]) -> Vec<(String, T)> {
    DOF_NAMES
        .iter()
        .zip(values)
        .map(|(n, v)| (n.to_string(), *v))
        .collect()
}

/// The initial guess's rotation sigmas (deg).
fn prior_rot_deg(r: &Refined) -> [f64; 3] {
    std::array::from_fn(|k| r.prior_sigma[k].to_degrees())
}

/// The initial guess's translation sigmas (m).
fn prior_trans_m(r: &Refined) -> [f64; 3] {
    std::array::from_fn(|k| r.prior_sigma[3 + k])
}

/// The DoFs the MI does not constrain (held, flat or not a maximum), with why.
fn unconstrained(r: &Refined) -> impl Iterator<Item = (&'static str, Constraint)> + '_ {
    DOF_NAMES
        .iter()
        .zip(&r.constraint)
        .filter(|(_, c)| c.is_unconstrained())
        .map(|(n, c)| (*n, *c))
}

/// The result file's `held` of a refinement: every DoF the MI does not constrain (held at
/// the initial value, flat, or not a maximum: its value is the initial guess's, not the
/// data's), by its index in `[rotation; translation]`.
pub fn held_dofs(r: &Refined) -> Vec<Dof> {
    (0..6)
        .filter(|&k| r.constraint[k].is_unconstrained())
        .filter_map(Dof::extrinsic)
        .collect()
}

/// Names of the DoFs the MI does not constrain.
fn unconstrained_names(r: &Refined) -> Vec<String> {
    unconstrained(r).map(|(n, _)| n.to_string()).collect()
}

/// Names of the DoFs the refinement held at their starting value.
fn held_names(r: &Refined) -> Vec<String> {
    DOF_NAMES
        .iter()
        .zip(&r.held)
        .filter(|(_, h)| **h)
        .map(|(n, _)| n.to_string())
        .collect()
}

/// Exit code 0 or 1 of a refinement: not converged, a DoF the MI does not constrain, or
/// one whose sigma moves the image by more than 3 px (`poor`).
pub fn outcome_of(refined: &Refined) -> Outcome {
    let unconstrained: Vec<String> = unconstrained(refined)
        .map(|(n, c)| format!("{n}: {}", c.why()))
        .collect();
    let poor: Vec<&str> = DOF_NAMES
        .iter()
        .zip(refined.observability.iter().zip(&refined.constraint))
        .filter(|(_, (o, c))| **o == Observability::Poor && !c.is_unconstrained())
        .map(|(n, _)| *n)
        .collect();
    let mut reasons = Vec::new();
    if !unconstrained.is_empty() {
        reasons.push(format!(
            "the MI does not constrain {} (reported as unconstrained, with the initial \
             guess's sigma; see docs/prior_map.md)",
            unconstrained.join("; ")
        ));
    }
    if !poor.is_empty() {
        reasons.push(format!(
            "one sigma of {} moves the image by more than 3 px",
            poor.join(", ")
        ));
    }
    if !refined.converged {
        Outcome::NotConverged("the MI refinement hit its iteration limit".into())
    } else if !reasons.is_empty() {
        Outcome::NotConverged(reasons.join("; "))
    } else {
        Outcome::Converged
    }
}

/// The scan file of `lidar0/` nearest in time to `stamp`.
fn nearest_scan(root: &Path, stamp: u64) -> anyhow::Result<PathBuf> {
    let dir = root.join("lidar0");
    list_scans(&dir)?
        .into_iter()
        .min_by_key(|s| s.stamp_ns.abs_diff(stamp))
        .map(|s| s.path)
        .ok_or_else(|| anyhow!("{}: no <timestamp_ns>.pcd scan", dir.display()))
}

/// Arguments of the targetless command (from `msreg calibrate lidar-camera --targetless`).
#[derive(Clone, Copy, Debug)]
pub struct TargetlessArgs<'a> {
    /// Dataset directory.
    pub dataset: &'a Path,
    /// Result file with the initial `cam0_lidar0.T_cam_lidar`.
    pub initial: Option<&'a Path>,
    /// Result YAML.
    pub output: &'a Path,
    /// JSON report.
    pub report: Option<&'a Path>,
    /// Overlay PNG (default: the output with extension png).
    pub overlay: Option<&'a Path>,
}

/// The initial `T_cam_lidar` from a result file and its sigma per DoF of `delta` (rad, m):
/// the file's when all six are positive, else [`default_prior_sigma`] (the search's basin).
fn read_initial(path: Option<&Path>) -> anyhow::Result<(Isometry3<f64>, Vector6<f64>)> {
    let path = path.ok_or_else(|| {
        anyhow!("--targetless needs --initial guess.yaml (a result file with cam0_lidar0)")
    })?;
    let result = CalibrationResult::read(path)?;
    let e = *result
        .extrinsic(&SectionName::CAM0_LIDAR0)
        .ok_or_else(|| anyhow!("{}: no cam0_lidar0.T_cam_lidar section", path.display()))?;
    let given = Vector6::new(
        e.sigma_rot_deg.x.to_radians(),
        e.sigma_rot_deg.y.to_radians(),
        e.sigma_rot_deg.z.to_radians(),
        e.sigma_trans_m.x,
        e.sigma_trans_m.y,
        e.sigma_trans_m.z,
    );
    let prior = if given.iter().all(|&s| s > 0.0) {
        given
    } else {
        default_prior_sigma()
    };
    Ok((e.transform, prior))
}

/// Runs the targetless calibration; `Err` is bad input (exit code 2).
pub fn calibrate(args: &TargetlessArgs<'_>) -> anyhow::Result<Outcome> {
    let (initial, prior_sigma) = read_initial(args.initial)?;
    let mut options = TargetlessOptions::default();
    options.refine.prior_sigma = prior_sigma;
    let root = args.dataset;
    let camera = read_camera_yaml(&root.join(CAMERA_YAML))?;
    let images = read_camera_csv(root.join(CAMERA_CSV))?;
    let (stamp, image_path) = images
        .first()
        .map(|f| (f.stamp_ns, f.path.clone()))
        .ok_or_else(|| anyhow!("{}: no image listed", root.join(CAMERA_CSV).display()))?;
    let image = GrayImage::load(&image_path)?;
    let scan_path = nearest_scan(root, stamp)?;
    let cloud = read_pcd(&scan_path)?;
    let clock = std::time::Instant::now();
    let result = match calibrate_targetless(&cloud, &image, &camera, &initial, &options) {
        Ok(r) => r,
        Err(e) => return Ok(Outcome::NotConverged(e.to_string())),
    };
    let seconds = clock.elapsed().as_secs_f64();
    let refined = &result.refined;
    let estimate = ExtrinsicEstimate::from_covariance(refined.x, 0.0, &refined.covariance);
    let mut file = CalibrationResult::new().with_extrinsic(SectionName::CAM0_LIDAR0, estimate);
    file.section_mut(SectionName::CAM0_LIDAR0)
        .hold_all(held_dofs(refined));
    let mut text = file.to_yaml_string();
    text.push_str(&mi_section("cam0_lidar0_mi", refined));
    write_result_and_report(
        &RunOutputs {
            result_path: args.output,
            result_yaml: &text,
            report_path: None,
            images: &[],
            figures: &[],
        },
        &(),
    )?;
    print_summary(args.output, &result, seconds);
    let overlay = args
        .overlay
        .map_or_else(|| args.output.with_extension("png"), Path::to_path_buf);
    write_overlay(&overlay, &image, &cloud, &camera, &refined.x)?;
    let before = overlay.with_file_name(format!(
        "{}_initial.png",
        overlay
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("overlay")
    ));
    write_overlay(&before, &image, &cloud, &camera, &initial)?;
    if let Some(path) = args.report {
        let report = make_report(args, &image_path, &scan_path, &result, seconds);
        msreg_host::report::write_report_for_result(
            path,
            &report,
            (args.output, &text),
            &[before.clone(), overlay.clone()],
            &[],
        )?;
    }
    Ok(outcome_of(refined))
}

/// A YAML section with the MI / NMI scores, per-DoF observability and constraint, and
/// the initial guess's sigmas (those of the unconstrained DoFs in the result).
pub fn mi_section(name: &str, r: &Refined) -> String {
    let per_dof = |f: &dyn Fn(usize) -> String| -> String {
        let items: Vec<String> = DOF_NAMES
            .iter()
            .enumerate()
            .map(|(k, n)| format!("{n}: {}", f(k)))
            .collect();
        items.join(", ")
    };
    let snake = |v: String| v.to_lowercase();
    let constraint = per_dof(&|k| r.constraint[k].as_str().into());
    let unconstrained = unconstrained_names(r).join(", ");
    let note = if unconstrained.is_empty() {
        String::new()
    } else {
        format!(
            "  # The MI does not constrain [{unconstrained}]: their sigmas in the result are the \
             initial guess's\n  # (prior_sigma_*), not information from the data.\n"
        )
    };
    format!(
        "{name}:\n{note}  mi: {}\n  nmi: {}\n  mi_hard: {}\n  nmi_hard: {}\n  samples: {}\n  \
         n_eff: {}\n  observability: {{{}}}\n  constraint: {{{constraint}}}\n  \
         unconstrained: [{unconstrained}]\n  held_at_initial: [{}]\n  \
         prior_sigma_rot_deg: {:?}\n  prior_sigma_trans_m: {:?}\n",
        r.smoothed.mi,
        r.smoothed.nmi,
        r.hard.mi,
        r.hard.nmi,
        r.smoothed.samples,
        r.n_eff,
        per_dof(&|k| snake(format!("{:?}", r.observability[k]))),
        held_names(r).join(", "),
        prior_rot_deg(r),
        prior_trans_m(r),
    )
}

fn print_summary(output: &Path, result: &TargetlessResult, seconds: f64) {
    let r = &result.refined;
    eprintln!(
        "msreg: wrote {} (MI {:.4} nats, NMI {:.4}, {} points, {} grid candidates, {} \
         iterations, {:.1} s)",
        output.display(),
        r.smoothed.mi,
        r.smoothed.nmi,
        result.points_used,
        result.grid_evaluations,
        r.iterations,
        seconds,
    );
    eprint!("{}", dof_table(r));
}

/// One line per DoF: its sigma and observability, or `unconstrained` and why (with the
/// initial guess's sigma that the result carries for it).
pub fn dof_table(r: &Refined) -> String {
    let mut text = String::from("msreg: per DoF (rotations in deg, translations in cm):\n");
    for (k, name) in DOF_NAMES.iter().enumerate() {
        let (scale, unit) = if k < 3 {
            (1f64.to_degrees(), "deg")
        } else {
            (100.0, "cm")
        };
        let prior = r.prior_sigma[k] * scale;
        let line = match r.constraint[k] {
            Constraint::Measured => format!(
                "sigma {:.3} {unit} ({})",
                r.covariance[(k, k)].max(0.0).sqrt() * scale,
                format!("{:?}", r.observability[k]).to_lowercase()
            ),
            c => format!(
                "unconstrained: {}; the result carries the initial guess's sigma {prior:.3} {unit}",
                c.why()
            ),
        };
        text.push_str(&format!("  {name:<6} {line}\n"));
    }
    text
}

fn make_report(
    args: &TargetlessArgs<'_>,
    image: &Path,
    scan: &Path,
    result: &TargetlessResult,
    seconds: f64,
) -> Report {
    let r = &result.refined;
    let m = r.x.to_homogeneous();
    Report {
        dataset: args.dataset.display().to_string(),
        image: image.display().to_string(),
        scan: scan.display().to_string(),
        points_used: result.points_used,
        grid_evaluations: result.grid_evaluations,
        mi_initial: f64::NAN,
        refined: RefinedSummary::of(r),
        t_cam_lidar: std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)])),
        seconds,
    }
}

/// A colour map from blue (0) through green to red (1).
fn colour(x: f32) -> [u8; 3] {
    let x = x.clamp(0.0, 1.0);
    let r = (1.5 - (4.0 * x - 3.0).abs()).clamp(0.0, 1.0);
    let g = (1.5 - (4.0 * x - 2.0).abs()).clamp(0.0, 1.0);
    let b = (1.5 - (4.0 * x - 1.0).abs()).clamp(0.0, 1.0);
    [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
}

/// The image (grey) with every point projected by `t_cam_src`, coloured by its
/// rank-normalised intensity (blue low, red high).
pub fn write_overlay(
    path: &Path,
    image: &GrayImage,
    cloud: &PointCloud,
    camera: &Camera<f64>,
    t_cam_src: &Isometry3<f64>,
) -> anyhow::Result<()> {
    let grey = image.to_luma8();
    let mut rgb = image::RgbImage::from_fn(grey.width(), grey.height(), |x, y| {
        let v = grey.get_pixel(x, y).0[0];
        image::Rgb([v, v, v])
    });
    let values: Vec<f32> = cloud.points.iter().map(|p| p.intensity).collect();
    let ranks = rank_normalize(&values);
    for (p, &rank) in cloud.points.iter().zip(&ranks) {
        let pc = t_cam_src * nalgebra::Point3::from(p.xyz);
        if pc.z < 0.5 {
            continue;
        }
        let Some(q) = camera.project(&pc.coords) else {
            continue;
        };
        let (u, v) = (q.pixel.x.round() as i64, q.pixel.y.round() as i64);
        for (x, y) in [(u, v), (u + 1, v), (u, v + 1), (u + 1, v + 1)] {
            if x >= 0 && y >= 0 && (x as u32) < rgb.width() && (y as u32) < rgb.height() {
                rgb.put_pixel(x as u32, y as u32, image::Rgb(colour(rank)));
            }
        }
    }
    rgb.save(path)
        .with_context(|| format!("{}: cannot write overlay", path.display()))
}
