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
use msreg_host::mi::scene::{highpass, PoseParam};
use msreg_host::mi::targetless::{
    calibrate_targetless, targetless_scene, visible_points, TargetlessOptions,
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
    /// Translation error per camera axis (x right, y down, z forward), m.
    trans_err_axes: Vector3<f64>,
    /// DoFs the refinement held (not determined by the MI).
    held: [bool; 6],
    seconds: f64,
    start: Isometry3<f64>,
    end: Isometry3<f64>,
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
    /// The pose the independent cues support: the reference rotated by
    /// [`EVIDENCE_ROTATION_DEG`] (translation unchanged; the forward translation is not
    /// determined by this frame).
    Evidence,
}

/// Right rotation increment (deg, LiDAR axes) from the published reference to the pose
/// the evidence supports: the inverse-variance mean of the lane markings, the ground MI
/// and the off-ground MI, `(+0.013, -0.344, +0.219) +- (0.056, 0.022, 0.055)` deg
/// (`tools/mi_cues.py`, docs/prior_map.md "Which pose does the evidence support?").
const EVIDENCE_ROTATION_DEG: [f64; 3] = [0.013, -0.344, 0.219];

fn run(draws: usize, seed: u64) -> Option<Vec<Draw>> {
    run_around(draws, seed, Centre::Reference)
}

/// `TargetlessOptions` with overrides from `MSREG_BASIN` (tuning runs only), e.g.
/// `blur=8,4,2;keep=4;sub=2;dofs=111110;rot=2;trans=0.1;hp=30;band=0.25;cand=2;steps=2`.
fn tuning_options() -> TargetlessOptions {
    let mut o = TargetlessOptions::default();
    let Ok(spec) = std::env::var("MSREG_BASIN") else {
        return o;
    };
    let mut b = o.basin.clone().unwrap_or_default();
    for kv in spec.split(';').filter(|s| !s.is_empty()) {
        let (k, v) = kv.split_once('=').expect("key=value");
        let f = |v: &str| v.parse::<f64>().expect("number");
        match k {
            "blur" => b.blur_px = v.split(',').map(f).collect(),
            "keep" => b.keep = f(v) as usize,
            "sub" => b.subsample = f(v) as usize,
            "psub" => b.probe_subsample = f(v) as usize,
            "steps" => b.steps = f(v) as usize,
            "tsteps" => b.trans_steps = f(v) as usize,
            "dofs" => b.grid_dofs = std::array::from_fn(|i| v.as_bytes()[i] == b'1'),
            "rot" => b.rot_deg = f(v),
            "trans" => b.trans_m = f(v),
            "hp" => o.highpass_px = f(v),
            "band" => o.ground_band_m = (f(v) > 0.0).then(|| f(v)),
            "offground" => o.off_ground_group = f(v) > 0.0,
            "cand" => o.refine_candidates = f(v) as usize,
            "margin" => o.margin_px = f(v),
            "refblur" => o.refine_blur_px = v.split(',').map(f).collect(),
            _ => panic!("unknown key {k}"),
        }
    }
    o.basin = (!b.blur_px.is_empty()).then_some(b);
    println!("options {o:?}");
    o
}

fn run_around(draws: usize, seed: u64, centre: Centre) -> Option<Vec<Draw>> {
    let dir = dir_or_skip("real/calibanything-1")?;
    let camera = read_camera_yaml(&dir.join("cam0/camera.yaml")).expect("camera.yaml");
    let image = GrayImage::load(&dir.join("cam0/data/1700000000000000000.png")).expect("png");
    let cloud = read_pcd(dir.join("lidar0/1700000000000000000.pcd")).expect("pcd");
    let reference = CalibrationResult::read(dir.join("groundtruth/extrinsics.yaml"))
        .expect("extrinsics.yaml")
        .get("cam0_lidar0")
        .copied()
        .expect("cam0_lidar0")
        .transform;
    let reference = match centre {
        Centre::Reference => reference,
        Centre::Evidence => {
            let w = EVIDENCE_ROTATION_DEG.map(f64::to_radians);
            PoseParam::CamFromSource
                .retract(&reference, &Vector6::new(w[0], w[1], w[2], 0.0, 0.0, 0.0))
        }
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
    let options = if seed == 7 {
        tuning_options()
    } else {
        TargetlessOptions::default()
    };
    // The MI of the final image level at any pose, on the points visible at the reference.
    let (p, i) = visible_points(&cloud, &camera, &reference, options.margin_px);
    let judged = if options.highpass_px > 0.0 {
        highpass(&image, options.highpass_px)
    } else {
        image.clone()
    };
    let judge = targetless_scene(p, &i, &judged, &camera, 1.0, &options);
    let mi = |t: &Isometry3<f64>| judge.smoothed(t).mi;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    for k in 0..draws {
        let start = PoseParam::CamFromSource.retract(&reference, &perturbation(&mut rng));
        let clock = std::time::Instant::now();
        let r = calibrate_targetless(&cloud, &image, &camera, &start, &options).expect("runs");
        let seconds = clock.elapsed().as_secs_f64();
        let (re, te) = errors(&reference, &r.refined.x);
        let axes = r.refined.x.translation.vector - reference.translation.vector;
        let rot_axes = (reference.rotation.inverse() * r.refined.x.rotation)
            .scaled_axis()
            .map(f64::to_degrees);
        if let Some(b) = &r.basin {
            for p in &b.probes {
                println!(
                    "  probe dof {}: mi {:.4?} sigma {:.2} px flat {}",
                    p.dof, p.mi, p.sigma_px, p.flat
                );
            }
        }
        let (rs, ts) = errors(&reference, &start);
        let sig = r.refined.covariance.diagonal().map(|v| v.max(0.0).sqrt());
        println!(
            "draw {k:2}: start {rs:.2} deg {:.1} cm -> {re:.3} deg {:.1} cm (LiDAR x y z {:.2?} \
             deg; camera x y z {:.1?} cm); \
             MI start {:.4} end {:.4} ref {:.4}; sigma rot {:.3?} deg trans {:.1?} cm; {:?}; \
             held {:?}; {seconds:.1} s",
            ts * 100.0,
            te * 100.0,
            rot_axes.as_slice(),
            (axes * 100.0).as_slice(),
            mi(&start),
            mi(&r.refined.x),
            mi(&reference),
            sig.fixed_rows::<3>(0).map(f64::to_degrees).as_slice(),
            (sig.fixed_rows::<3>(3) * 100.0).as_slice(),
            r.refined.observability,
            r.refined.held
        );
        out.push(Draw {
            rot_err_deg: re,
            trans_err_m: te,
            trans_err_axes: axes,
            held: r.refined.held,
            seconds,
            start,
            end: r.refined.x,
            start_rot_deg: rs,
            start_trans_m: ts,
            mi_start: mi(&start),
            mi_end: mi(&r.refined.x),
            mi_ref: mi(&reference),
        });
    }
    Some(out)
}

/// Translation error (m) over the camera axes the refinement did not hold.
fn observable_trans_err(d: &Draw) -> f64 {
    (0..3)
        .filter(|&a| !d.held[3 + a])
        .map(|a| d.trans_err_axes[a].powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Within 0.3 deg and, over the translation axes reported observable (not held), 5 cm.
fn observable_ok(d: &Draw) -> bool {
    d.rot_err_deg <= 0.3 && observable_trans_err(d) <= 0.05
}

/// Prints the judge on the observable DoFs and the worst cases; returns the count.
fn observable_summary(draws: &[Draw]) -> usize {
    let ok = draws.iter().filter(|d| observable_ok(d)).count();
    let worst = |f: fn(&Draw) -> f64| draws.iter().map(f).fold(0.0, f64::max);
    println!(
        "{ok} of {} within 0.3 deg and 5 cm over the observable translation axes; worst \
         {:.3} deg, {:.1} cm observable, {:.1} cm total; held z on {} of {}; {:.1} s max",
        draws.len(),
        worst(|d| d.rot_err_deg),
        worst(observable_trans_err) * 100.0,
        worst(|d| d.trans_err_m) * 100.0,
        draws.iter().filter(|d| d.held[5]).count(),
        draws.len(),
        worst(|d| d.seconds)
    );
    ok
}

/// Held camera-frame translation axes end exactly where they started.
fn held_axes_unchanged(d: &Draw) -> bool {
    (0..3).all(|a| {
        !d.held[3 + a]
            || d.end.translation.vector[a].to_bits() == d.start.translation.vector[a].to_bits()
    })
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
        return;
    };
    summary(&draws);
    for d in &draws {
        assert!(d.rot_err_deg.is_finite() && d.trans_err_m.is_finite());
        assert!(d.mi_end.is_finite() && d.mi_start.is_finite());
        // The search ends higher than it started, and a held DoF does not move.
        assert!(d.mi_end > d.mi_start, "MI {} -> {}", d.mi_start, d.mi_end);
        assert!(held_axes_unchanged(d));
    }
}

#[test]
#[ignore = "20-draw acceptance run (3-6 min on 2 loaded cores): cargo test --release -p msreg --test mi_targetless_real -- --ignored --nocapture"]
fn targetless_refinement_returns_to_the_reference_on_18_of_20() {
    let Some(draws) = run(20, 20) else {
        return;
    };
    let ok = summary(&draws);
    assert!(ok >= 18, "only {ok} of 20 within 0.3 deg / 5 cm");
}

/// The 20 draws of seed 20 around the pose the evidence supports (docs/prior_map.md,
/// "Which pose does the evidence support?").
#[test]
#[ignore = "evidence-pose draws (3-8 min): cargo test --release -p msreg --test mi_targetless_real around_the_evidence -- --ignored --nocapture"]
fn targetless_refinement_around_the_evidence_pose() {
    let Some(draws) = run_around(20, 20, Centre::Evidence) else {
        return;
    };
    summary(&draws);
    observable_summary(&draws);
    // Measured (docs/prior_map.md): 18 of 20 within 0.3 deg (worst 0.448 deg, median
    // 0.14); 19 of 20 end above the evidence pose's MI; over the translation axes not
    // held, worst 5.1 cm; `z` held on 15 of 20. Bounds about 3x (counts: 3x the misses).
    let rot_ok = draws.iter().filter(|d| d.rot_err_deg <= 0.3).count();
    assert!(rot_ok >= 14, "{rot_ok} of 20 within 0.3 deg");
    let above = draws.iter().filter(|d| d.mi_end > d.mi_ref).count();
    assert!(
        above >= 17,
        "{above} of 20 end above the evidence pose's MI"
    );
    let mut rot: Vec<f64> = draws.iter().map(|d| d.rot_err_deg).collect();
    rot.sort_by(f64::total_cmp);
    assert!(rot[10] < 0.42, "median rotation error {} deg", rot[10]);
    let held_z = draws.iter().filter(|d| d.held[5]).count();
    assert!(held_z >= 10, "z held on {held_z} of 20");
    for d in &draws {
        assert!(d.rot_err_deg < 1.35, "rotation error {} deg", d.rot_err_deg);
        assert!(observable_trans_err(d) < 0.153);
        assert!(held_axes_unchanged(d));
    }
}

/// The draws the search's constants (blur levels, spacing, candidates kept, the
/// off-ground group, the probe's significance test) were chosen on: seed 7, not the tests'
/// 15 / 20. Around the evidence pose by default; `MSREG_CENTRE=reference|markings`
/// moves the centre. Prints the same summaries.
#[test]
#[ignore = "tuning draws (seed 7): cargo test --release -p msreg --test mi_targetless_real tuning -- --ignored --nocapture"]
fn tuning_draws() {
    let centre = match std::env::var("MSREG_CENTRE").as_deref() {
        Ok("reference") => Centre::Reference,
        Ok("markings") => Centre::MarkingAligned,
        _ => Centre::Evidence,
    };
    let Some(draws) = run_around(20, 7, centre) else {
        return;
    };
    summary(&draws);
    observable_summary(&draws);
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

/// The command from the published reference with a guess file that gives its own sigmas
/// (1.5 deg, 8 cm): the result file reads back through the result reader; every sigma is
/// finite and at most the guess's; each DoF listed `unconstrained` carries exactly the
/// guess's sigma and is named with its reason on stderr; the forward translation `z`
/// (undetermined by every cue on this frame, docs/prior_map.md) is among them; exit 1.
#[test]
fn targetless_cli_reports_unconstrained_dofs_with_the_guess_sigma() {
    let Some(dir) = dir_or_skip("real/calibanything-1") else {
        return;
    };
    let out = std::env::temp_dir().join(format!("msreg_mi_cli_{}", std::process::id()));
    std::fs::create_dir_all(&out).expect("temp dir");
    let reference =
        std::fs::read_to_string(dir.join("groundtruth/extrinsics.yaml")).expect("extrinsics.yaml");
    let guess = out.join("guess.yaml");
    let prior = [1.5, 1.5, 1.5, 0.08, 0.08, 0.08];
    std::fs::write(
        &guess,
        format!(
            "{reference}  sigma_rot_deg: [1.5, 1.5, 1.5]\n  sigma_trans_m: [0.08, 0.08, 0.08]\n"
        ),
    )
    .expect("write guess");
    let result = out.join("r.yaml");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(["calibrate", "lidar-camera"])
        .arg(&dir)
        .arg("--targetless")
        .arg("--initial")
        .arg(&guess)
        .arg("-o")
        .arg(&result)
        .arg("--report")
        .arg(out.join("r.json"))
        .output()
        .expect("msreg runs");
    let stderr = String::from_utf8_lossy(&run.stderr);
    eprintln!("{stderr}");
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    let estimate = CalibrationResult::read(&result)
        .expect("result reads back")
        .get("cam0_lidar0")
        .copied()
        .expect("cam0_lidar0");
    let sigma: Vec<f64> = estimate
        .sigma_rot_deg
        .iter()
        .chain(estimate.sigma_trans_m.iter())
        .copied()
        .collect();
    let yaml: serde_yaml::Value =
        serde_yaml::from_str(&std::fs::read_to_string(&result).expect("result")).expect("yaml");
    let names = ["rot_x", "rot_y", "rot_z", "x", "y", "z"];
    let unconstrained: Vec<String> =
        serde_yaml::from_value(yaml["cam0_lidar0_mi"]["unconstrained"].clone())
            .expect("unconstrained list");
    assert!(unconstrained.iter().any(|n| n == "z"), "{unconstrained:?}");
    for (k, name) in names.iter().enumerate() {
        assert!(sigma[k].is_finite() && sigma[k] > 0.0 && sigma[k] <= prior[k] + 1e-12);
        let free = !unconstrained.iter().any(|n| n == name);
        let constraint = yaml["cam0_lidar0_mi"]["constraint"][name]
            .as_str()
            .expect("constraint");
        assert_eq!(free, constraint == "measured", "{name}: {constraint}");
        if !free {
            assert!((sigma[k] - prior[k]).abs() < 1e-12, "{name}: {}", sigma[k]);
            let line = stderr
                .lines()
                .find(|l| l.trim_start().starts_with(&format!("{name} ")))
                .expect("per-DoF line");
            assert!(line.contains("unconstrained:"), "{line}");
        }
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("r.json")).expect("report"))
            .expect("json");
    let listed: Vec<String> =
        serde_json::from_value(report["unconstrained"].clone()).expect("report list");
    assert_eq!(listed, unconstrained);
    std::fs::remove_dir_all(&out).ok();
}
