//! `msreg calibrate infra` on simulated buildings, judged frame-free against the truth.
//!
//! Default: 2 seeds at the settings (40 cameras). Full run (5 seeds plus a
//! repeatability pair): `cargo test --release -p msreg-host --test infra_calibrate -- --ignored
//! --nocapture`; numbers in docs/infra.md.

use msreg_host::infra::align::rigid;
use msreg_host::infra::dataset::InfraDataset;
use msreg_host::infra::eval::{evaluate, InfraErrors};
use msreg_host::infra::io::{pose_of_rows, InfraResultFile};
use msreg_host::infra::pipeline::{calibrate, InfraCalibration};
use msreg_host::infra::sim::{simulate, InfraSimConfig};

fn run(seed: u64, building_seed: u64) -> (InfraCalibration, InfraResultFile, InfraDataset) {
    let sim = simulate(&InfraSimConfig {
        seed,
        building_seed,
        ..InfraSimConfig::default()
    });
    let dir = tempfile::tempdir().expect("tempdir");
    sim.write(dir.path()).expect("write");
    let data = InfraDataset::open(dir.path()).expect("read");
    let cal = calibrate(&data).expect("calibrate");
    let truth = InfraResultFile::read(&dir.path().join("groundtruth/infra.yaml")).expect("truth");
    (cal, truth, data)
}

fn judged(seed: u64) -> InfraErrors {
    let (cal, truth, _) = run(seed, seed);
    assert!(
        cal.report.cameras.iter().all(|c| c.solved),
        "{:?}",
        cal.report.cameras.iter().find(|c| !c.solved)
    );
    let e = evaluate(&cal.result, &truth).expect("evaluate");
    let m = cal.report.motion.as_ref().expect("motion");
    eprintln!(
        "seed {seed}: cameras {} pos RMS {:.3} m (max {:.3}), rot max {:.3} deg, scale err {:+.4} %, inside 3 sigma {:.1} %, motion pairs {}, T_F_M weak directions {}",
        e.cameras, e.position_rms_m, e.position_max_m, e.rotation_max_deg, 100.0 * e.scale_error, 100.0 * e.inside_3sigma, m.pairs, m.degeneracy.len()
    );
    e
}

/// Camera-centre RMS between two independent runs of one building after one rigid alignment.
fn repeatability(seed_a: u64, seed_b: u64, building: u64) -> f64 {
    let (a, _, _) = run(seed_a, building);
    let (b, _, _) = run(seed_b, building);
    let mut pa = Vec::new();
    let mut pb = Vec::new();
    for (id, ca) in &a.result.infra.cameras {
        if let Some(cb) = b.result.infra.cameras.get(id) {
            let here = std::path::Path::new("-");
            pa.push(
                pose_of_rows(here, &ca.t_world_cam)
                    .expect("a")
                    .translation
                    .vector,
            );
            pb.push(
                pose_of_rows(here, &cb.t_world_cam)
                    .expect("b")
                    .translation
                    .vector,
            );
        }
    }
    let t = rigid(&pa, &pb);
    let sq: f64 = pa
        .iter()
        .zip(&pb)
        .map(|(x, y)| (t * nalgebra::Point3::from(*x) - nalgebra::Point3::from(*y)).norm_squared())
        .sum();
    (sq / pa.len() as f64).sqrt()
}

#[test]
fn registers_forty_cameras_two_seeds() {
    for seed in [11, 12] {
        let e = judged(seed);
        assert_eq!(e.cameras, 40);
        // Tolerances ~3x the worst measured over seeds 0-4 and 11-12 (docs/infra.md), the
        // rotation at the 0.2 deg (measured worst 0.12 deg).
        assert!(e.position_rms_m < 0.015, "{e:?}");
        assert!(e.rotation_max_deg < 0.2, "{e:?}");
        assert!(e.scale_error.abs() < 0.0005, "{e:?}");
        assert!(e.inside_3sigma >= 0.95, "{e:?}");
    }
}

#[test]
#[ignore = "acceptance run: 5 seeds + repeatability, ~80 s release"]
fn acceptance_five_seeds() {
    let all: Vec<InfraErrors> = (0..5).map(judged).collect();
    let rep = repeatability(100, 101, 7);
    eprintln!("repeatability (building 7, runs 100/101): {rep:.3} m RMS");
    let worst = |f: fn(&InfraErrors) -> f64| all.iter().map(f).fold(0.0, f64::max);
    eprintln!(
        "worst: pos RMS {:.3} m, rot max {:.3} deg, |scale err| {:.4} %, min inside 3 sigma {:.1} %",
        worst(|e| e.position_rms_m),
        worst(|e| e.rotation_max_deg),
        100.0 * worst(|e| e.scale_error.abs()),
        100.0 * all.iter().map(|e| e.inside_3sigma).fold(1.0, f64::min)
    );
    assert!(
        worst(|e| e.position_rms_m) < 0.03,
        "positions (issue: < 3 cm RMS)"
    );
    assert!(
        worst(|e| e.rotation_max_deg) < 0.2,
        "rotations (issue: < 0.2 deg)"
    );
    assert!(
        worst(|e| e.scale_error.abs()) < 0.002,
        "scale (issue: < 0.2 %)"
    );
    assert!(
        all.iter().all(|e| e.inside_3sigma >= 0.95),
        "consistency (issue: >= 95 %)"
    );
    assert!(rep < 0.03, "repeatability (issue: < 3 cm)");
}

#[test]
fn cameras_without_usable_detections_are_reported_and_the_others_solved() {
    let sim = simulate(&InfraSimConfig {
        seed: 21,
        building_seed: 21,
        ..InfraSimConfig::default()
    });
    let dir = tempfile::tempdir().expect("tempdir");
    sim.write(dir.path()).expect("write");
    // c03: no markers.csv at all; c07: only 2 detections left.
    std::fs::remove_file(dir.path().join("infra/c03/markers.csv")).expect("rm");
    let p = dir.path().join("infra/c07/markers.csv");
    let text = std::fs::read_to_string(&p).expect("read");
    std::fs::write(&p, text.lines().take(3).collect::<Vec<_>>().join("\n")).expect("write");
    let data = InfraDataset::open(dir.path()).expect("the dataset as a whole is readable");
    let cal = calibrate(&data).expect("calibrate");
    let failed: Vec<&str> = cal
        .report
        .cameras
        .iter()
        .filter(|c| !c.solved)
        .map(|c| c.id.as_str())
        .collect();
    assert_eq!(failed, ["c03", "c07"]);
    let why = |id: &str| {
        cal.report
            .cameras
            .iter()
            .find(|c| c.id == id)
            .and_then(|c| c.reason.clone())
            .unwrap_or_default()
    };
    assert!(why("c03").contains("markers.csv"), "{}", why("c03"));
    assert!(
        why("c07").contains("usable marker detections") && why("c07").contains("(2 in the file)"),
        "{}",
        why("c07")
    );
    let truth = InfraResultFile::read(&dir.path().join("groundtruth/infra.yaml")).expect("truth");
    let e = evaluate(&cal.result, &truth).expect("evaluate");
    assert_eq!(e.cameras, 38);
    assert!(e.position_rms_m < 0.015, "{e:?}");
}
