//! The prior-map registration on simulated intersections (issue 15 acceptance): from a GPS
//! prior 3 m off with unknown yaw, automatic ORB + PnP initialisation, then the MI grid and
//! refinement. Judged against the simulator's truth: camera position, yaw, every component
//! inside its reported 3 sigma, and the survey points' reprojection error.
//!
//! `ci_sized_registration_converges` runs by default (small images and map, one seed);
//! `acceptance_five_seeds` is the full-size acceptance (ignored; numbers in
//! docs/prior_map.md).

use msreg_host::dataset::ExtrinsicEstimate;
use msreg_host::mi::prior_map::input::read_input;
use msreg_host::mi::prior_map::{median, register, survey_errors, yaw_error, RegisterOptions};
use msreg_host::sim::prior_map::{simulate_prior_map, PriorMapSimConfig};

/// Errors of one run.
#[derive(Debug)]
struct Outcome {
    init_inliers: usize,
    position_cm: f64,
    yaw_deg: f64,
    survey_median_px: f64,
    survey_median_initial_px: f64,
    worst_sigma_ratio: f64,
    sigma_pos_cm: [f64; 3],
    sigma_rot_deg: [f64; 3],
    /// Per DoF: the slice's peak offset in slice steps (0 = at the estimate).
    slice_peak_steps: Vec<f64>,
    /// Per DoF: the slice's second difference over +-1 step divided by the refinement's
    /// `H_kk` (1 = the curvature the sigmas come from is the slice's).
    slice_curvature_ratio: Vec<f64>,
}

fn run(config: &PriorMapSimConfig) -> Result<Outcome, String> {
    let sim = simulate_prior_map(config);
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    sim.write(dir.path()).map_err(|e| e.to_string())?;
    let input = read_input(dir.path()).map_err(|e| e.to_string())?;
    let reg = register(&input, &RegisterOptions::default()).map_err(|e| e.to_string())?;
    let truth = sim.t_world_cam;
    let x = reg.refined.x;
    let dp = x.translation.vector - truth.translation.vector;
    let dr = (truth.rotation.inverse() * x.rotation).scaled_axis();
    let sig = reg.refined.covariance.diagonal().map(|v| v.max(0.0).sqrt());
    let ratio = (0..3)
        .map(|k| (dr[k] / sig[k]).abs().max((dp[k] / sig[k + 3]).abs()))
        .fold(0.0, f64::max);
    let est = ExtrinsicEstimate::from_covariance(x, 0.0, &reg.refined.covariance);
    let (slice_peak_steps, slice_curvature_ratio) = reg
        .slices
        .iter()
        .map(|s| {
            let c = s.offsets.len() / 2;
            let step = s.offsets[c + 1] - s.offsets[c];
            let second = (s.mi[c + 1] + s.mi[c - 1] - 2.0 * s.mi[c])
                / (s.quadratic[c + 1] + s.quadratic[c - 1] - 2.0 * s.quadratic[c]);
            (s.peak_offset / step, second)
        })
        .unzip();
    Ok(Outcome {
        init_inliers: reg.init.inliers,
        position_cm: dp.norm() * 100.0,
        yaw_deg: yaw_error(&x, &truth).to_degrees(),
        survey_median_px: median(&survey_errors(&input.camera, &x, &input.survey)),
        survey_median_initial_px: median(&survey_errors(
            &input.camera,
            &reg.init.t_world_cam,
            &input.survey,
        )),
        worst_sigma_ratio: ratio,
        sigma_pos_cm: (est.sigma_trans_m * 100.0).into(),
        sigma_rot_deg: est.sigma_rot_deg.into(),
        slice_peak_steps,
        slice_curvature_ratio,
    })
}

fn passes(o: &Outcome) -> bool {
    let sigmas_valid = o
        .sigma_pos_cm
        .iter()
        .chain(&o.sigma_rot_deg)
        .all(|s| s.is_finite() && *s > 0.0);
    sigmas_valid
        && o.position_cm < 10.0
        && o.yaw_deg.abs() < 0.2
        && o.survey_median_px < 3.0
        && o.worst_sigma_ratio <= 3.0
}

#[test]
fn ci_sized_registration_converges() {
    let config = PriorMapSimConfig {
        prior_offset_m: Some(3.0),
        ..PriorMapSimConfig::small(11)
    };
    let o = run(&config).expect("registration runs");
    eprintln!("small seed 11: {o:?}");
    assert!(passes(&o), "{o:?}");
    // Measured (seed 11): 1.9 cm, 0.002 deg, survey median 0.08 px (initial 0.40 px),
    // worst component 2.0 sigma, 27 verified matches. About 3x:
    assert!(o.init_inliers >= 12, "{o:?}");
    assert!(o.position_cm < 6.0, "{o:?}");
    assert!(o.yaw_deg.abs() < 0.01, "{o:?}");
    assert!(o.survey_median_px < 0.25, "{o:?}");
    assert!(o.survey_median_px < o.survey_median_initial_px, "{o:?}");
    // MI slices (+-3 px of image motion, 6 steps a side): each peaks at the estimate.
    assert_eq!(o.slice_peak_steps.len(), 6, "{o:?}");
    assert!(o.slice_peak_steps.iter().all(|&p| p == 0.0), "{o:?}");
    // Their second difference at +-0.5 px against the refinement's H_kk: measured
    // 1.076-1.087 (seed 11); about 3x the deviation from 1:
    assert!(
        o.slice_curvature_ratio
            .iter()
            .all(|r| (0.74..1.26).contains(r)),
        "{o:?}"
    );
}

#[test]
#[ignore = "full-size acceptance, 5 seeds (minutes); numbers in docs/prior_map.md"]
fn acceptance_five_seeds() {
    let mut converged = 0;
    for seed in 1..=5 {
        let config = PriorMapSimConfig {
            prior_offset_m: Some(3.0),
            seed,
            ..PriorMapSimConfig::default()
        };
        let o = run(&config);
        eprintln!("seed {seed}: {o:?}");
        if o.as_ref().is_ok_and(passes) {
            converged += 1;
        }
    }
    eprintln!("{converged} of 5 converged");
    assert!(converged >= 4, "{converged} of 5");
}
