//! The camera-IMU simulator through the detector (issue 3's detector acceptance on rendered
//! images): over several seeds, the corners detected in the simulator's 8-bit images are
//! within 0.1 px RMS of the true corners when clean and 0.3 px with motion blur, lighting
//! gradient and noise; frames without the full board yield no detection; the written dataset
//! reads back through the dataset readers and `CameraDataset`, and bad input is reported.

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use msreg_host::dataset::{
    read_corners_csv, read_target_poses_csv, CornerTruth, Dataset, CAMERA_YAML, TARGET_YAML,
};
use msreg_host::sim::camera::{simulate_camera_imu, CameraImuSim, CameraImuSimConfig};
use msreg_host::vision::{
    detect_checkerboard, solve_pnp, CameraDataset, CameraInputError, DetectorParams, GrayImage,
    NoDetection,
};

fn config(seed: u64, duration_s: f64) -> CameraImuSimConfig {
    CameraImuSimConfig {
        seed,
        duration_s,
        ..CameraImuSimConfig::default()
    }
}

/// What a PNG round trip gives: 8-bit grey levels.
fn quantised(img: &GrayImage) -> GrayImage {
    GrayImage::from_luma8(&img.to_luma8())
}

/// Detection statistics over frames `0, step, 2 step, ...` of `sim`.
struct Stats {
    frames: usize,
    in_view: usize,
    detected: usize,
    false_detections: usize,
    sum_sq: f64,
    corners: usize,
    worst_frame_rms: f64,
}

fn run(sim: &CameraImuSim, step: usize) -> Stats {
    let params = DetectorParams::default();
    let b = &sim.config.board;
    let mut s = Stats {
        frames: 0,
        in_view: 0,
        detected: 0,
        false_detections: 0,
        sum_sq: 0.0,
        corners: 0,
        worst_frame_rms: 0.0,
    };
    for k in (0..sim.frame_stamps.len()).step_by(step) {
        s.frames += 1;
        let full = sim.full_board_in_view(k);
        s.in_view += usize::from(full);
        let img = quantised(&sim.image(k));
        let Ok(det) = detect_checkerboard(&img, b.rows, b.cols, &params) else {
            continue;
        };
        if !full {
            s.false_detections += 1;
            continue;
        }
        s.detected += 1;
        let truth = sim.true_corners(k);
        let sq: f64 = det
            .corners
            .iter()
            .zip(&truth)
            .map(|(p, t)| (p - t.unwrap()).norm_squared())
            .sum();
        s.sum_sq += sq;
        s.corners += det.corners.len();
        s.worst_frame_rms = s
            .worst_frame_rms
            .max((sq / det.corners.len() as f64).sqrt());
    }
    s
}

fn rms(s: &Stats) -> f64 {
    (s.sum_sq / s.corners.max(1) as f64).sqrt()
}

fn check_accuracy(realistic: bool, limit_px: f64) {
    for seed in [1, 2, 3] {
        let mut c = config(seed, 20.0);
        if realistic {
            c = c.with_blur_and_noise();
        }
        let sim = simulate_camera_imu(&c).unwrap();
        let s = run(&sim, 10);
        println!(
            "seed {seed} {}: {}/{} frames detected ({} with the full board in view), \
             RMS {:.4} px over {} corners, worst frame {:.4} px",
            if realistic { "blur+noise" } else { "clean" },
            s.detected,
            s.frames,
            s.in_view,
            rms(&s),
            s.corners,
            s.worst_frame_rms
        );
        assert_eq!(s.false_detections, 0, "seed {seed}");
        assert!(
            s.detected * 10 >= s.in_view * 9,
            "seed {seed}: detection rate"
        );
        assert!(rms(&s) < limit_px, "seed {seed}: RMS {:.3} px", rms(&s));
    }
}

#[test]
fn clean_simulated_frames_give_corners_within_0_1_px() {
    check_accuracy(false, 0.1);
}

#[test]
fn blurred_noisy_simulated_frames_give_corners_within_0_3_px() {
    check_accuracy(true, 0.3);
}

#[test]
fn frames_without_the_full_board_yield_no_detection() {
    // A wild hand: the camera wanders far enough that the board often leaves the view.
    let mut partial = 0;
    for seed in [4, 5] {
        let mut c = config(seed, 12.0).with_blur_and_noise();
        c.look_at.distance_m = 0.6;
        c.look_at.max_deviation_rad = [0.6, 0.6, 0.8];
        c.trajectory.rate_amplitude_rad_s = 2.0;
        let sim = simulate_camera_imu(&c).unwrap();
        let s = run(&sim, 4);
        println!(
            "seed {seed}: {} frames, {} with the full board, {} detected, {} false",
            s.frames, s.in_view, s.detected, s.false_detections
        );
        partial += s.frames - s.in_view;
        assert_eq!(s.false_detections, 0, "seed {seed}");
        assert!(rms(&s) < 0.3, "seed {seed}");
    }
    assert!(
        partial >= 20,
        "too few frames without the full board: {partial}"
    );
}

fn write_small(dir: &std::path::Path) -> CameraImuSim {
    let sim = simulate_camera_imu(&config(7, 2.0)).unwrap();
    sim.write(dir, &|_| {}).unwrap();
    sim
}

#[test]
fn the_written_dataset_reads_back_and_detects_like_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let sim = write_small(dir.path());
    let ds = Dataset::open(dir.path()).unwrap();
    assert_eq!(ds.require_imu().unwrap().len(), sim.imu.len());
    let truth = *ds
        .require_groundtruth_extrinsics()
        .unwrap()
        .get("cam0")
        .unwrap();
    assert!((truth.transform.inverse() * sim.t_cam_imu).rotation.angle() < 1e-12);
    let cam = CameraDataset::open(dir.path()).unwrap();
    assert_eq!(cam.camera, sim.config.camera);
    assert_eq!(cam.target.corner_count(), 6 * 7);
    assert_eq!(cam.frames.len(), sim.frame_stamps.len());
    let poses = read_target_poses_csv(dir.path().join("groundtruth/target_poses.csv")).unwrap();
    assert_eq!(poses.len(), cam.frames.len());
    assert!(
        (poses[0].isometry().inverse() * sim.t_g_target)
            .translation
            .vector
            .norm()
            < 1e-12
    );
    let corners: Vec<CornerTruth> =
        read_corners_csv(dir.path().join("groundtruth/corners.csv")).unwrap();
    assert_eq!(corners.len(), 42 * cam.frames.len());
    let results = cam.detect(&DetectorParams::default(), &|_| {}).unwrap();
    let mut detected = 0;
    for (k, r) in results.iter().enumerate() {
        let Ok(c) = &r.corners else { continue };
        detected += 1;
        // Ids, target frame, trajectory and mounting agree end to end: PnP on the detected
        // corners gives the true T_cam_target at the frame's IMU time.
        let pnp = solve_pnp(&cam.camera, &c.target_points(&cam.target), &c.pixels).unwrap();
        let truth = sim.t_cam_target(sim.frame_time(k));
        assert!((pnp.t_cam_target.translation - truth.translation).norm() < 2e-3);
        assert!(pnp.t_cam_target.rotation.angle_to(&truth.rotation) < 0.2_f64.to_radians());
        for (id, p) in c.ids.iter().zip(&c.pixels) {
            let t = corners
                .iter()
                .find(|t| t.stamp_ns == r.stamp_ns && t.corner_id == *id)
                .unwrap();
            assert!(t.in_image && (p - t.pixel).norm() < 0.3, "{r:?}");
        }
    }
    assert!(
        detected * 10 >= results.len() * 9,
        "{detected}/{}",
        results.len()
    );
}

#[test]
fn bad_camera_inputs_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let sim = write_small(dir.path());
    let frames = CameraDataset::open(dir.path()).unwrap().frames;

    // Unknown camera model: the error names camera.yaml and its line.
    let camera_yaml = dir.path().join(CAMERA_YAML);
    let good_camera = std::fs::read_to_string(&camera_yaml).unwrap();
    std::fs::write(&camera_yaml, good_camera.replace("pinhole", "kannala")).unwrap();
    let msg = CameraDataset::open(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("camera.yaml:2:") && msg.contains("kannala"),
        "{msg}"
    );
    std::fs::write(&camera_yaml, &good_camera).unwrap();

    // A plain board is not a checkerboard.
    let target_yaml = dir.path().join(TARGET_YAML);
    let good_target = std::fs::read_to_string(&target_yaml).unwrap();
    std::fs::write(
        &target_yaml,
        "target_type: board\nwidth_m: 1\nheight_m: 1\n",
    )
    .unwrap();
    let err = CameraDataset::open(dir.path()).unwrap_err();
    assert!(
        matches!(err, CameraInputError::NotCornerTarget { .. }),
        "{err}"
    );

    // Wrong target size: every frame is rejected with the reason, none reported.
    std::fs::write(
        &target_yaml,
        good_target.replace("targetCols: 7", "targetCols: 8"),
    )
    .unwrap();
    let results = CameraDataset::open(dir.path())
        .unwrap()
        .detect(&DetectorParams::default(), &|_| {})
        .unwrap();
    assert!(results
        .iter()
        .all(|r| matches!(r.corners, Err(NoDetection::Partial { .. }))));
    std::fs::write(
        &target_yaml,
        good_target.replace("targetRows: 6", "targetRows: 5"),
    )
    .unwrap();
    let results = CameraDataset::open(dir.path())
        .unwrap()
        .detect(&DetectorParams::default(), &|_| {})
        .unwrap();
    let larger = results
        .iter()
        .filter(|r| matches!(r.corners, Err(NoDetection::LargerThanTarget { .. })))
        .count();
    assert!(results.iter().all(|r| r.corners.is_err()) && larger * 2 > results.len());
    std::fs::write(&target_yaml, &good_target).unwrap();

    // A corrupt image, then a missing one: errors naming the image.
    let victim = &frames[3].path;
    std::fs::write(victim, b"\x89PNG\r\n\x1a\ntruncated").unwrap();
    let cam = CameraDataset::open(dir.path()).unwrap();
    let err = cam.detect(&DetectorParams::default(), &|_| {}).unwrap_err();
    assert!(matches!(err, CameraInputError::Image(_)), "{err}");
    assert!(
        err.to_string().contains(&victim.display().to_string()),
        "{err}"
    );
    std::fs::remove_file(victim).unwrap();
    let err = cam.detect(&DetectorParams::default(), &|_| {}).unwrap_err();
    assert!(
        err.to_string().contains(&victim.display().to_string()),
        "{err}"
    );

    // An image of the wrong size.
    sim.image(0);
    let small = GrayImage::new(320, 240, 100.0).to_luma8();
    small.save(victim).unwrap();
    let err = cam.detect(&DetectorParams::default(), &|_| {}).unwrap_err();
    assert!(
        matches!(err, CameraInputError::SizeMismatch { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("320x240"), "{err}");

    // cam0/data.csv missing.
    std::fs::remove_file(dir.path().join("cam0/data.csv")).unwrap();
    let msg = CameraDataset::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("cam0/data.csv"), "{msg}");
}

/// RMS against the truth of the frames detected by both parameter sets.
fn paired_rms(
    sim: &CameraImuSim,
    step: usize,
    a: &DetectorParams,
    b: &DetectorParams,
) -> (f64, f64, usize) {
    let board = &sim.config.board;
    let (mut sa, mut sb, mut n) = (0.0, 0.0, 0);
    for k in (0..sim.frame_stamps.len()).step_by(step) {
        let img = quantised(&sim.image(k));
        let (Ok(da), Ok(db)) = (
            detect_checkerboard(&img, board.rows, board.cols, a),
            detect_checkerboard(&img, board.rows, board.cols, b),
        ) else {
            continue;
        };
        for ((pa, pb), t) in da.corners.iter().zip(&db.corners).zip(sim.true_corners(k)) {
            let t = t.unwrap();
            sa += (pa - t).norm_squared();
            sb += (pb - t).norm_squared();
            n += 1;
        }
    }
    let n_f = n.max(1) as f64;
    ((sa / n_f).sqrt(), (sb / n_f).sqrt(), n)
}

/// Why the default refinement window is capped at half the corner spacing: on a fisheye
/// image with ~15 px squares (the real fisheye set's smallest), OpenCV's fixed 23 x 23
/// window reaches the neighbouring corners and is pulled off the junction; the capped window
/// is less so. Measured against the simulator's true corners: per seed the two are within
/// 0.007 px except where the large window is pulled (0.114 vs 0.060 px), see
/// docs/checkerboard.md.
#[test]
fn on_small_fisheye_squares_the_capped_window_is_more_accurate_overall() {
    let (mut sum_default, mut sum_opencv, mut total) = (0.0, 0.0, 0);
    for seed in [8, 9, 10, 11] {
        let mut c = config(seed, 8.0).with_blur_and_noise();
        c.camera = msreg_host::sim::CameraModelChoice::PinholeEquidistant.camera();
        c.look_at.distance_m = 1.2;
        let sim = simulate_camera_imu(&c).unwrap();
        let (default, opencv, n) = paired_rms(
            &sim,
            8,
            &DetectorParams::default(),
            &DetectorParams::opencv_compatible(),
        );
        println!(
            "seed {seed}: fisheye, board at 1.2 m: RMS vs truth over {n} corners: default \
             {default:.4} px, opencv_compatible {opencv:.4} px"
        );
        assert!(n >= 10 * 42, "seed {seed}: only {n} corners");
        assert!(default < 0.1, "seed {seed}: {default}");
        sum_default += default * default * n as f64;
        sum_opencv += opencv * opencv * n as f64;
        total += n;
    }
    let (default, opencv) = (
        (sum_default / total as f64).sqrt(),
        (sum_opencv / total as f64).sqrt(),
    );
    println!("all seeds: default {default:.4} px, opencv_compatible {opencv:.4} px");
    assert!(default < opencv);
}
