//! Targetless (MI) LiDAR-camera calibration on the real CalibAnything scan + image: from
//! the published reference perturbed by up to 2 deg / 10 cm, how close does the
//! refinement come back? Numbers and discussion: docs/prior_map.md.
//!
//! The fast version (3 draws) runs by default and asserts only what holds (it runs,
//! errors and MI are finite; numbers printed); the 20-draw acceptance run of issue 15 is
//! `cargo test --release -p msreg --test mi_targetless_real -- --ignored --nocapture`.

use msreg_host::camera_yaml::read_camera_yaml;
use msreg_host::dataset::CalibrationResult;
use msreg_host::mi::markings::{align_rotation, MarkingOptions};
use msreg_host::mi::scene::{highpass, MiScene, PoseParam};
use msreg_host::mi::targetless::{
    calibrate_targetless, ground_band, visible_points, TargetlessOptions,
};
use msreg_host::pointcloud::read_pcd;
use msreg_host::shared_data::dir_or_skip;
use msreg_host::vision::GrayImage;
use nalgebra::{Isometry3, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

struct Draw {
    rot_err_deg: f64,
    trans_err_m: f64,
    start_rot_deg: f64,
    start_trans_m: f64,
    mi_start: f64,
    mi_end: f64,
    mi_ref: f64,
}

/// A random perturbation: rotation angle up to 2 deg, translation up to 10 cm, uniform
/// random directions.
fn perturbation(rng: &mut ChaCha8Rng) -> Vector6<f64> {
    let dir = |rng: &mut ChaCha8Rng| {
        Vector3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        )
        .normalize()
    };
    let w = dir(rng) * rng.gen_range(0.0..2.0f64).to_radians();
    let v = dir(rng) * rng.gen_range(0.0..0.10);
    Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
}

fn errors(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (
        d.rotation.angle().to_degrees(),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

/// Which pose the draws perturb and are judged against.
#[derive(Clone, Copy, PartialEq)]
enum Centre {
    /// The published reference.
    Reference,
    /// The reference with its rotation aligned to the lane markings
    /// (`msreg_host::mi::markings`; translation unchanged).
    MarkingAligned,
}

fn run(draws: usize, seed: u64) -> Option<Vec<Draw>> {
    run_around(draws, seed, Centre::Reference)
}

fn run_around(draws: usize, seed: u64, centre: Centre) -> Option<Vec<Draw>> {
    let dir = dir_or_skip("real/calibanything-1")?;
    let camera = read_camera_yaml(&dir.join("cam0/camera.yaml")).expect("camera.yaml");
    let image = GrayImage::load(&dir.join("cam0/data/1700000000000000000.png")).expect("png");
    let cloud = read_pcd(dir.join("lidar0/1700000000000000000.pcd")).expect("pcd");
    let reference = CalibrationResult::read(dir.join("groundtruth/extrinsics.yaml"))
        .expect("extrinsics.yaml")
        .cam0_lidar0
        .expect("cam0_lidar0")
        .transform;
    let reference = match centre {
        Centre::Reference => reference,
        Centre::MarkingAligned => {
            align_rotation(
                &cloud,
                &image,
                &camera,
                &reference,
                &MarkingOptions::default(),
                3,
            )
            .expect("marking crossings")
            .t_cam_lidar
        }
    };
    let options = TargetlessOptions::default();
    // The MI of the final image level at any pose, on the points visible at the reference.
    let (p, i) = visible_points(&cloud, &camera, &reference, options.margin_px);
    let (p, i) = match options.ground_band_m {
        Some(b) => ground_band(&p, &i, b),
        None => (p, i),
    };
    let judged = if options.highpass_px > 0.0 {
        highpass(&image, options.highpass_px)
    } else {
        image.clone()
    };
    let judge = MiScene::new(p, &i, &judged, camera, 1.0);
    let mi = |t: &Isometry3<f64>| judge.smoothed(t).mi;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    for k in 0..draws {
        let start = PoseParam::CamFromSource.retract(&reference, &perturbation(&mut rng));
        let r = calibrate_targetless(&cloud, &image, &camera, &start, &options).expect("runs");
        let (re, te) = errors(&reference, &r.refined.x);
        let (rs, ts) = errors(&reference, &start);
        let sig = r.refined.covariance.diagonal().map(|v| v.max(0.0).sqrt());
        println!(
            "draw {k:2}: start {rs:.2} deg {:.1} cm -> {re:.3} deg {:.1} cm; MI start {:.4} \
             end {:.4} ref {:.4}; sigma rot {:.3?} deg trans {:.1?} cm; {:?}",
            ts * 100.0,
            te * 100.0,
            mi(&start),
            mi(&r.refined.x),
            mi(&reference),
            sig.fixed_rows::<3>(0).map(f64::to_degrees).as_slice(),
            (sig.fixed_rows::<3>(3) * 100.0).as_slice(),
            r.refined.observability
        );
        out.push(Draw {
            rot_err_deg: re,
            trans_err_m: te,
            start_rot_deg: rs,
            start_trans_m: ts,
            mi_start: mi(&start),
            mi_end: mi(&r.refined.x),
            mi_ref: mi(&reference),
        });
    }
    Some(out)
}

fn summary(draws: &[Draw]) -> usize {
    let ok = draws
        .iter()
        .filter(|d| d.rot_err_deg <= 0.3 && d.trans_err_m <= 0.05)
        .count();
    let better = draws
        .iter()
        .filter(|d| d.rot_err_deg < d.start_rot_deg && d.trans_err_m < d.start_trans_m)
        .count();
    let above_ref = draws.iter().filter(|d| d.mi_end > d.mi_ref).count();
    let rot_ok = draws.iter().filter(|d| d.rot_err_deg <= 0.3).count();
    let trans_ok = draws.iter().filter(|d| d.trans_err_m <= 0.05).count();
    let median = |f: fn(&Draw) -> f64| {
        let mut v: Vec<f64> = draws.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{ok} of {} within 0.3 deg / 5 cm ({rot_ok} within 0.3 deg, {trans_ok} within 5 cm; \
         median {:.2} deg, {:.1} cm); {better} closer than their start in both; \
         {above_ref} end with a higher MI than the centre pose",
        draws.len(),
        median(|d| d.rot_err_deg),
        median(|d| d.trans_err_m) * 100.0
    );
    ok
}

#[test]
fn targetless_refinement_on_real_data_runs_and_reports_finite_errors() {
    let Some(draws) = run(3, 15) else {
        eprintln!("SKIP: ../shared/data/real/calibanything-1 absent");
        return;
    };
    summary(&draws);
    for d in &draws {
        assert!(d.rot_err_deg.is_finite() && d.trans_err_m.is_finite());
        assert!(d.mi_end.is_finite() && d.mi_start.is_finite());
    }
}

#[test]
#[ignore = "20-draw acceptance run (~15 s): cargo test --release -p msreg --test mi_targetless_real -- --ignored --nocapture"]
fn targetless_refinement_returns_to_the_reference_on_18_of_20() {
    let Some(draws) = run(20, 20) else {
        eprintln!("SKIP: ../shared/data/real/calibanything-1 absent");
        return;
    };
    let ok = summary(&draws);
    assert!(ok >= 18, "only {ok} of 20 within 0.3 deg / 5 cm");
}

/// Diagnostic, not the acceptance: the same draws around the marking-aligned pose (the
/// reference is 0.27 deg off in pitch by the lane markings, docs/prior_map.md). Prints the
/// same summary; asserts only that it runs.
#[test]
#[ignore = "diagnostic (~20-50 s): cargo test --release -p msreg --test mi_targetless_real -- --ignored --nocapture"]
fn targetless_refinement_around_the_marking_aligned_pose() {
    let Some(draws) = run_around(20, 20, Centre::MarkingAligned) else {
        eprintln!("SKIP: ../shared/data/real/calibanything-1 absent");
        return;
    };
    summary(&draws);
    assert!(draws.iter().all(|d| d.rot_err_deg.is_finite()));
}

#[test]
fn targetless_without_initial_or_with_a_bad_one_is_bad_input() {
    let Some(dir) = dir_or_skip("real/calibanything-1") else {
        return;
    };
    let out = std::env::temp_dir().join(format!("msreg_mi_{}", std::process::id()));
    std::fs::create_dir_all(&out).expect("temp dir");
    let run = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_msreg"))
            .args(["calibrate", "lidar-camera"])
            .arg(&dir)
            .arg("--targetless")
            .args(extra)
            .arg("-o")
            .arg(out.join("r.yaml"))
            .output()
            .expect("msreg runs")
    };
    let missing = run(&[]);
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("--initial"));
    let guess = out.join("guess.yaml");
    std::fs::write(&guess, "cam0_lidar0:\n  T_cam_lidar: [[1, 0]]\n").expect("write");
    let bad = run(&["--initial", guess.to_str().expect("utf-8")]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("guess.yaml"));
    std::fs::remove_dir_all(&out).ok();
}
