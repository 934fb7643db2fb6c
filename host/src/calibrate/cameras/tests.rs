//! Simulated acceptance of the camera calibration: corners projected through a true model
//! from random target poses with Gaussian pixel noise (the models' own projection, not the
//! estimator's starting values), one to two cameras.

use super::*;
use crate::solve::SchurProblem;
use msreg_estimator::camera::model::CameraModel;
use nalgebra::{Rotation3, Unit, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Views per camera of the accuracy tests: a 10 s recording at 20 Hz.
const VIEWS: usize = 200;

/// Corner noise of the accuracy tests, px (1-sigma per axis).
const SIGMA_PX: f64 = 0.1;

/// One true camera of every kind.
fn truths() -> Vec<CameraModel<f64>> {
    let m = |k, p: &[f64], r| CameraModel::new(k, p, r).unwrap();
    vec![
        m(
            ModelKind::PinholeRadtan,
            &[458.6, 457.3, 367.2, 248.4, -0.283, 0.074, 0.0002, 1.8e-5],
            (752, 480),
        ),
        m(
            ModelKind::PinholeEquidistant,
            &[290.0, 289.4, 399.9, 273.9, -0.03, -0.02, 0.0021, 0.001],
            (800, 503),
        ),
        m(
            ModelKind::OmniRadtan,
            &[0.9, 750.0, 748.0, 640.0, 480.0, -0.2, 0.05, 0.001, -0.001],
            (1280, 960),
        ),
        m(
            ModelKind::DoubleSphere,
            &[-0.18, 0.59, 313.2, 313.1, 638.9, 514.0],
            (1280, 1024),
        ),
        m(
            ModelKind::Eucm,
            &[0.63, 1.05, 380.1, 380.0, 640.2, 511.8],
            (1280, 1024),
        ),
    ]
}

/// A 9 x 12 grid of corners, 4 cm apart.
fn board() -> Vec<Vector3<f64>> {
    (0..108)
        .map(|id| Vector3::new((id / 12) as f64 * 0.04, (id % 12) as f64 * 0.04, 0.0))
        .collect()
}

/// The widest off-axis angle the image of `cam` reaches along its axes, capped at 75 deg.
fn field_angle(cam: &CameraModel<f64>) -> f64 {
    let (w, h) = (f64::from(cam.resolution.0), f64::from(cam.resolution.1));
    let k = cam.pinhole();
    [
        Vector2::new(0.0, k.cv),
        Vector2::new(w - 1.0, k.cv),
        Vector2::new(k.cu, 0.0),
        Vector2::new(k.cu, h - 1.0),
    ]
    .iter()
    .filter_map(|p| cam.unproject(p))
    .map(|b| b.z.acos())
    .fold(f64::INFINITY, f64::min)
    .min(75f64.to_radians())
}

/// `T_c0_target` of a board centred on the ray of a random pixel of `cam` (at most
/// `max_angle` off the axis), tilted and spun.
fn random_view(rng: &mut ChaCha8Rng, cam: &CameraModel<f64>, max_angle: f64) -> Pose<f64> {
    let (w, h) = (f64::from(cam.resolution.0), f64::from(cam.resolution.1));
    let px = Vector2::new(rng.gen_range(0.0..w), rng.gen_range(0.0..h));
    let ray = cam.unproject(&px).unwrap_or_else(Vector3::z);
    let a = ray.z.acos().min(max_angle);
    let phi = ray.y.atan2(ray.x);
    let dir = Vector3::new(a.sin() * phi.cos(), a.sin() * phi.sin(), a.cos());
    let distance = rng.gen_range(0.35..0.9);
    // Board normal towards the camera, tilted up to 40 deg, spun about itself.
    let tilt_axis = Unit::new_normalize(dir.cross(&Vector3::new(
        rng.gen_range(-1.0..1.0),
        rng.gen_range(-1.0..1.0),
        0.3,
    )));
    let tilt = Rotation3::from_axis_angle(&tilt_axis, rng.gen_range(-0.7..0.7));
    let facing = Rotation3::rotation_between(&Vector3::z(), &(tilt * -dir))
        .unwrap_or_else(Rotation3::identity);
    let spin = Rotation3::from_axis_angle(&Vector3::z_axis(), rng.gen_range(-3.1..3.1));
    let r = facing * spin;
    let centre = Vector3::new(0.16, 0.22, 0.0);
    let t = dir * distance - r * centre;
    Pose::new(UnitQuaternion::from_rotation_matrix(&r), t)
}

/// Target points and their pixels.
type Corners2d = (Vec<Vector3<f64>>, Vec<Vector2<f64>>);

/// Noisy corners of camera `cam` (extrinsic `t_c_c0`) in a view, those inside the image.
fn observe(
    rng: &mut ChaCha8Rng,
    cam: &CameraModel<f64>,
    t_c_c0: &Pose<f64>,
    view: &Pose<f64>,
    sigma: f64,
) -> Option<Corners2d> {
    let noise = Normal::new(0.0, sigma).unwrap();
    let (mut points, mut pixels) = (Vec::new(), Vec::new());
    for x in board() {
        let p = t_c_c0.transform_point(&view.transform_point(&x));
        let Some((px, _, _)) = cam.project(&p) else {
            continue;
        };
        let b = cam.unproject(&px);
        if p.z < 0.05 * p.norm() || b.is_none() || !in_image(cam, &px, 3.0) {
            continue;
        }
        points.push(x);
        pixels.push(px + Vector2::new(noise.sample(rng), noise.sample(rng)));
    }
    (points.len() >= 30).then_some((points, pixels))
}

fn in_image(cam: &CameraModel<f64>, px: &Vector2<f64>, margin: f64) -> bool {
    let (w, h) = (f64::from(cam.resolution.0), f64::from(cam.resolution.1));
    px.x >= margin && px.y >= margin && px.x <= w - 1.0 - margin && px.y <= h - 1.0 - margin
}

/// Inputs of `cams` (with extrinsics `T_cn_c0`) over `views` random views.
fn simulate(
    seed: u64,
    cams: &[(CameraModel<f64>, Pose<f64>)],
    views: usize,
    sigma: f64,
) -> Vec<CameraInput> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let max_angle = cams
        .iter()
        .map(|c| field_angle(&c.0))
        .fold(f64::INFINITY, f64::min);
    let mut inputs: Vec<CameraInput> = cams
        .iter()
        .enumerate()
        .map(|(c, (m, _))| CameraInput {
            name: format!("cam{c}"),
            kind: m.kind,
            resolution: m.resolution,
            images: Vec::new(),
        })
        .collect();
    let mut v = 0;
    while inputs.iter().map(|i| i.images.len()).min().unwrap_or(0) < views && v < 50 * views {
        let view = random_view(&mut rng, &cams[0].0, max_angle);
        v += 1;
        for (c, (m, ext)) in cams.iter().enumerate() {
            if let Some((points, pixels)) = observe(&mut rng, m, ext, &view, sigma) {
                inputs[c].images.push(ImageCorners {
                    stamp_ns: v as u64 * 50_000_000,
                    name: format!("{v}.png"),
                    points,
                    pixels,
                });
            }
        }
    }
    inputs
}

/// The grid points of a 25 x 19 grid of pixels of the true camera where the data reached
/// (at least 3 observed corners in their cell, half a grid step either way), with their
/// true bearings.
fn covered_rays(
    truth: &CameraModel<f64>,
    input: &CameraInput,
) -> Vec<(Vector2<f64>, Vector3<f64>)> {
    let (w, h) = (f64::from(truth.resolution.0), f64::from(truth.resolution.1));
    let (du, dv) = ((w - 1.0) / 24.0, (h - 1.0) / 18.0);
    let mut count = [[0usize; 19]; 25];
    for p in input.images.iter().flat_map(|im| im.pixels.iter()) {
        let (i, j) = ((p.x / du).round() as usize, (p.y / dv).round() as usize);
        if i < 25 && j < 19 {
            count[i][j] += 1;
        }
    }
    let mut rays = Vec::new();
    for (i, column) in count.iter().enumerate() {
        for (j, n) in column.iter().enumerate() {
            let px = Vector2::new(i as f64 * du, j as f64 * dv);
            if let (true, Some(b)) = (*n >= 3, truth.unproject(&px)) {
                rays.push((px, b));
            }
        }
    }
    rays
}

/// Worst pixel distance between the true pixel of each covered ray and its projection by
/// the estimate, the rays first turned by `rotation`.
fn worst_of(
    est: &CameraModel<f64>,
    rays: &[(Vector2<f64>, Vector3<f64>)],
    rotation: &Rotation3<f64>,
) -> f64 {
    rays.iter()
        .map(|(px, b)| {
            est.project(&(rotation * b))
                .map_or(f64::INFINITY, |(q, _, _)| (q - px).norm())
        })
        .fold(0.0, f64::max)
}

/// The ray-grid error as the camera frame defines it (the principal point's uncertainty
/// included: a shift of it is nearly a small rotation of every target pose).
fn worst_ray_error_raw(
    truth: &CameraModel<f64>,
    est: &CameraModel<f64>,
    input: &CameraInput,
) -> f64 {
    worst_of(est, &covered_rays(truth, input), &Rotation3::identity())
}

/// The ray-grid error after the rotation that best aligns the estimated camera frame with
/// the true one (Kabsch on the bearings of the grid pixels): the intrinsics' error without
/// the part a camera-frame rotation absorbs, which any extrinsic calibration takes up.
fn worst_ray_error(truth: &CameraModel<f64>, est: &CameraModel<f64>, input: &CameraInput) -> f64 {
    let rays = covered_rays(truth, input);
    let mut m = nalgebra::Matrix3::zeros();
    for (px, b) in &rays {
        if let Some(e) = est.unproject(px) {
            m += e * b.transpose();
        }
    }
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let d = (u * vt).determinant().signum();
    let r = u * nalgebra::Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    worst_of(est, &rays, &Rotation3::from_matrix_unchecked(r))
}

/// Two-sided 99 % band of the mean of `runs` chi2(`dof`) draws (Wilson-Hilferty).
fn nees_band(dof: usize, runs: usize) -> (f64, f64) {
    let k = (dof * runs) as f64;
    let q = |z: f64| k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3);
    (q(-2.576) / runs as f64, q(2.576) / runs as f64)
}

fn intrinsic_nees(truth: &CameraModel<f64>, res: &CamerasResult, c: usize) -> f64 {
    let layout = Layout::of(&res.cameras.iter().map(|c| c.model).collect::<Vec<_>>());
    let n = truth.kind.param_count();
    let s = layout.intrinsics[c];
    let cov = res.covariance.view((s, s), (n, n)).into_owned();
    let e = nalgebra::DVector::from_iterator(
        n,
        (0..n).map(|k| res.cameras[c].model.params[k] - truth.params[k]),
    );
    (e.transpose() * cov.try_inverse().unwrap() * &e)[0]
}

#[test]
fn every_model_recovers_its_intrinsics_within_0_1_px_and_consistently() {
    for truth in truths() {
        let mut nees = Vec::new();
        let (mut worst, mut raw_worst): (f64, f64) = (0.0, 0.0);
        for seed in 0..10 {
            let inputs = simulate(100 + seed, &[(truth, Pose::identity())], VIEWS, SIGMA_PX);
            let res = calibrate_cameras(&inputs, &CamerasOptions::default()).unwrap();
            let est = res.cameras[0].model;
            let err = worst_ray_error(&truth, &est, &inputs[0]);
            let raw = worst_ray_error_raw(&truth, &est, &inputs[0]);
            raw_worst = raw_worst.max(raw);
            if std::env::var("MSREG_CAMERAS_DEBUG").is_ok() {
                println!(
                    "  {:?} seed {seed}: {err:.3} {:?}",
                    truth.kind,
                    est.values()
                );
            }
            worst = worst.max(err);
            nees.push(intrinsic_nees(&truth, &res, 0));
            assert!(res.converged, "{:?} seed {seed}", truth.kind);
        }
        let mean = nees.iter().sum::<f64>() / nees.len() as f64;
        let band = nees_band(truth.kind.param_count(), nees.len());
        println!(
            "{:>20}: worst ray error {worst:.4} px over 10 seeds (before the rotation \
             alignment {raw_worst:.4} px); mean NEES {mean:.2} (dof {}, 99 % band {:.2}..{:.2})",
            truth.kind.name(),
            truth.kind.param_count(),
            band.0,
            band.1
        );
        assert!(worst < 0.1, "{:?}: {worst}", truth.kind);
        assert!(
            band.0 < mean && mean < band.1,
            "{:?}: NEES {mean} {band:?}",
            truth.kind
        );
    }
}

fn stereo_truth() -> Pose<f64> {
    Pose::new(
        UnitQuaternion::from_euler_angles(0.01, -0.02, 0.005),
        Vector3::new(-0.11, 0.002, 0.001),
    )
}

#[test]
fn a_stereo_pair_lands_within_0_02_deg_and_0_2_mm_consistently() {
    let cams = [truths()[0], truths()[0]];
    let mut cam1 = cams[1];
    cam1.params[0] += 3.0;
    cam1.params[2] -= 5.0;
    let truth_ext = stereo_truth();
    let (mut nees, mut worst_rot, mut worst_trans) = (Vec::new(), 0.0f64, 0.0f64);
    for seed in 0..10 {
        let inputs = simulate(
            200 + seed,
            &[(cams[0], Pose::identity()), (cam1, truth_ext)],
            VIEWS,
            SIGMA_PX,
        );
        let res = calibrate_cameras(&inputs, &CamerasOptions::default()).unwrap();
        let (t, cov) = res.cameras[1].t_cn_cnm1.unwrap();
        let e = pose_error(&t, &truth_ext);
        worst_rot = worst_rot.max(e.fixed_rows::<3>(0).norm().to_degrees());
        worst_trans = worst_trans.max(e.fixed_rows::<3>(3).norm());
        nees.push((e.transpose() * cov.try_inverse().unwrap() * e)[0]);
        assert!(worst_ray_error(&cam1, &res.cameras[1].model, &inputs[1]) < 0.1);
    }
    let mean = nees.iter().sum::<f64>() / 10.0;
    let band = nees_band(6, 10);
    println!(
        "stereo: worst {worst_rot:.4} deg, {:.4} mm; mean NEES {mean:.2} (99 % band {:.2}..{:.2})",
        worst_trans * 1e3,
        band.0,
        band.1
    );
    assert!(worst_rot < 0.02 && worst_trans < 0.0002);
    assert!(band.0 < mean && mean < band.1, "{mean} {band:?}");
}

#[test]
fn outlying_corners_and_images_are_rejected_and_counted() {
    let truth = truths()[0];
    let mut inputs = simulate(7, &[(truth, Pose::identity())], 30, 0.3);
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let mut gross = 0;
    for im in inputs[0].images.iter_mut().skip(1) {
        for p in im.pixels.iter_mut() {
            if rng.gen_range(0.0..1.0) < 0.02 {
                *p += Vector2::new(rng.gen_range(6.0..12.0), rng.gen_range(-12.0..-6.0));
                gross += 1;
            }
        }
    }
    // One blurred image: every corner off by 2 px (1-sigma per axis).
    let blur = Normal::new(0.0, 2.0).unwrap();
    for p in inputs[0].images[0].pixels.iter_mut() {
        *p += Vector2::new(blur.sample(&mut rng), blur.sample(&mut rng));
    }
    let res = calibrate_cameras(&inputs, &CamerasOptions::default()).unwrap();
    let cam = &res.cameras[0];
    let nees = intrinsic_nees(&truth, &res, 0);
    let in_image0 = inputs[0].images[0].pixels.len();
    println!(
        "{gross} gross corners injected and a blurred image of {in_image0}; rejected {} corners, \
         {} images; rms {:.3} px; intrinsics NEES {nees:.2} (8 dof)",
        cam.corners.1, cam.images.1, cam.rms_px
    );
    assert_eq!(cam.images.1, 1);
    assert!(!cam.image_rms[0].2);
    assert!(cam.corners.1 >= gross + in_image0 && cam.corners.1 <= gross + in_image0 + 40);
    // chi2(8) at 0.999: the outliers leave no bias beyond the estimate's own uncertainty.
    assert!(nees < 26.1, "{nees}");
}

#[test]
fn zhang_recovers_an_undistorted_pinhole_exactly() {
    let k = CameraModel::new(
        ModelKind::PinholeRadtan,
        &[500.0, 480.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0],
        (640, 480),
    )
    .unwrap();
    let inputs = simulate(3, &[(k, Pose::identity())], 6, 0.0);
    let hs: Vec<_> = inputs[0]
        .images
        .iter()
        .filter_map(|im| init::homography(&im.points, &im.pixels))
        .collect();
    let z = init::zhang(&hs).unwrap();
    assert!(
        (z.fu - 500.0).abs() < 1e-6 && (z.fv - 480.0).abs() < 1e-6,
        "{z:?}"
    );
    assert!(
        (z.cu - 320.0).abs() < 1e-6 && (z.cv - 240.0).abs() < 1e-6,
        "{z:?}"
    );
}

#[test]
fn the_problem_jacobians_match_central_differences() {
    let (truth, ext) = (truths()[2], stereo_truth());
    let inputs = simulate(5, &[(truths()[3], Pose::identity()), (truth, ext)], 2, 0.0);
    let corners = build_corners(&inputs, 1000);
    let cams = vec![truths()[3], truth];
    let state = RigState {
        extrinsics: vec![Pose::identity(), ext],
        views: (0..corners.views)
            .map(|v| random_view(&mut ChaCha8Rng::seed_from_u64(v as u64), &truth, 0.3))
            .collect(),
        cameras: cams,
    };
    let problem = RigProblem {
        observations: &corners.observations,
        views: corners.views,
        layout: Layout::of(&state.cameras),
        weight: 1.0,
    };
    let mut base = Vec::new();
    assert!(problem.residuals(&state, &mut base));
    let g = problem.global_dim();
    let h = 1e-6;
    for k in 0..g + 6 {
        let mut dg = nalgebra::DVector::zeros(g);
        let mut dl = vec![Vector6::zeros(); corners.views];
        if k < g {
            dg[k] = h;
        } else {
            dl[0][k - g] = h;
        }
        let neg: Vec<Vector6<f64>> = dl.iter().map(|d| -d).collect();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        problem.residuals(&problem.retract(&state, &dg, &dl), &mut a);
        problem.residuals(&problem.retract(&state, &-&dg, &neg), &mut b);
        for (i, r) in base.iter().enumerate() {
            let numeric = (a[i].value - b[i].value) / (2.0 * h);
            let analytic = if k < g {
                (0..r.global_len)
                    .find(|&c| r.global_index[c] == k)
                    .map_or(Vector2::zeros(), |c| r.j_global.column(c).into_owned())
            } else if r.local == 0 {
                r.j_local.column(k - g).into_owned()
            } else {
                Vector2::zeros()
            };
            let scale = 1.0 + analytic.norm();
            assert!(
                (numeric - analytic).norm() < 1e-4 * scale,
                "param {k} residual {i}: {numeric} vs {analytic}"
            );
        }
    }
}

#[test]
fn a_ds_and_eucm_camera_yaml_round_trips() {
    for truth in truths() {
        let text = crate::camera_yaml::camera_model_yaml_string(&truth);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.yaml");
        std::fs::write(&path, &text).unwrap();
        let spec = crate::camera_yaml::read_camera_spec(&path).unwrap();
        assert_eq!(spec.kind, truth.kind);
        assert_eq!(spec.model, Some(truth), "{text}");
    }
}

#[test]
fn unsynchronised_cameras_are_refused_naming_them_and_the_difference() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("target.yaml"), "target_type: checkerboard\ntargetRows: 6\ntargetCols: 9\nrowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n").unwrap();
    for (c, offset) in [(0, 0u64), (1, 7_000_000)] {
        let cam = dir.path().join(format!("cam{c}"));
        std::fs::create_dir_all(cam.join("data")).unwrap();
        std::fs::write(
            cam.join("camera.yaml"),
            "camera_model: pinhole\ndistortion_model: radtan\nresolution: [640, 480]\n",
        )
        .unwrap();
        let rows: String = (0..10)
            .map(|i| format!("{},{i}.png\n", 1_000_000_000 + i * 50_000_000 + offset))
            .collect();
        std::fs::write(
            cam.join("data.csv"),
            format!("#timestamp [ns],filename\n{rows}"),
        )
        .unwrap();
    }
    let ds = dataset::CamerasDataset::open(dir.path(), &[]).unwrap();
    assert_eq!(ds.cameras.len(), 2);
    let err = ds.check_sync(1_000_000).unwrap_err().to_string();
    assert!(
        err.contains("cam1 and cam0 are not synchronised") && err.contains("7.000 ms"),
        "{err}"
    );
    assert!(ds.check_sync(10_000_000).is_ok());
}
