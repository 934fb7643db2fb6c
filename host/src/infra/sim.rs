//! `msreg simulate infra`: sensors of the infrastructure-camera scenario simulated from the
//! geometry of [`super::scene`] alone.
//!
//! - Marker corners: the true marker corners projected by each camera's own lens at the
//!   frames of its own free-running clock (period 95-105 ms, random phase: no two cameras
//!   and no camera and `F` share a stamp), 0.3 px Gaussian noise, 1 % of the corners
//!   displaced by 4-20 px (outliers). A detection needs all four corners 3 px inside the
//!   image, the face within 75 deg of the line of sight and a side of >= 10 px (marker side 0.5 m).
//! - Blobs: at each `F` keyframe, every camera centre within 15 m that `F` images, seen with
//!   probability 0.95, 1 px noise; plus Poisson(1.5) clutter blobs inside the image circle.
//! - VO: keyframes every 0.6 s. The relative motion between consecutive keyframes is
//!   perturbed by a random walk (rotation 0.25 deg / sqrt(m) per axis, translation
//!   5 mm / sqrt(m)), which drifts about 1 % of the distance; the trajectory is then put in
//!   an arbitrary frame at an arbitrary scale (0.2-5 m per unit). Map points are anchored
//!   at the drifted pose of the first keyframe that sees them (+1 cm noise), as a VO does;
//!   the keypoints are the true projections + 0.5 px noise.
//! - Randomness: ChaCha8 seeded with `seed`; building, robot/VO and detections use separate
//!   streams, so `building_seed` keeps the building while `seed` changes the run.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};

use super::colmap::{ColmapImage, ColmapModel};
use super::io::{Blob, MarkerDetection, MarkerSpec};
use super::scene::{self, InfraCamera, RobotMotion, SceneConfig};
use msreg_estimator::camera::Camera;

/// First stamp of every simulated clock, ns.
pub const BASE_STAMP_NS: u64 = 1_700_000_000_000_000_000;

/// Simulator settings.
#[derive(Clone, Debug)]
pub struct InfraSimConfig {
    /// Seed of the run (robot noise, VO, detections).
    pub seed: u64,
    /// Seed of the building (cameras, ceiling); defaults to `seed`.
    pub building_seed: u64,
    /// The building.
    pub scene: SceneConfig,
    /// Keyframe period, s.
    pub keyframe_period_s: f64,
    /// Marker-corner noise, px.
    pub marker_noise_px: f64,
    /// Fraction of marker corners that are outliers.
    pub marker_outlier_fraction: f64,
    /// Blob noise, px.
    pub blob_noise_px: f64,
    /// Mean clutter blobs per keyframe.
    pub clutter_per_keyframe: f64,
    /// VO rotation random walk, rad / sqrt(m), per axis.
    pub vo_rot_walk: f64,
    /// VO translation random walk, m / sqrt(m), per axis.
    pub vo_trans_walk: f64,
    /// VO keypoint noise, px.
    pub keypoint_noise_px: f64,
    /// Printed marker side, m.
    pub marker_side_m: f64,
}

impl Default for InfraSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            building_seed: 0,
            scene: SceneConfig::default(),
            keyframe_period_s: 0.6,
            marker_noise_px: 0.3,
            marker_outlier_fraction: 0.01,
            blob_noise_px: 1.0,
            clutter_per_keyframe: 1.5,
            vo_rot_walk: 0.25f64.to_radians(),
            vo_trans_walk: 0.005,
            keypoint_noise_px: 0.5,
            marker_side_m: 0.5,
        }
    }
}

/// A simulated dataset with its ground truth.
#[derive(Clone, Debug)]
pub struct InfraSim {
    /// The robot's fisheye `F` (cam0).
    pub f_camera: Camera<f64>,
    /// The marker.
    pub marker: MarkerSpec,
    /// True `T_F_M`.
    pub t_f_m: Isometry3<f64>,
    /// Infrastructure cameras with their true poses.
    pub cameras: Vec<InfraCamera>,
    /// Marker detections per camera (same order).
    pub detections: Vec<Vec<MarkerDetection>>,
    /// The true marker pose `T_C_M` at each detection of `detections` (same order): what
    /// `--images` renders.
    pub marker_views: Vec<Vec<(u64, Isometry3<f64>)>>,
    /// Blob detections in F keyframes.
    pub blobs: Vec<Blob>,
    /// Per keyframe: the true pixels of every camera centre within range in view of F, and
    /// the clutter spots: what `--images` renders.
    pub blob_views: Vec<KeyframeSpots>,
    /// The VO as a COLMAP model (OpenCV pixels inside; the writer adds 0.5).
    pub vo: ColmapModel,
    /// True `T_W_F` at each keyframe.
    pub keyframe_truth: Vec<Isometry3<f64>>,
    /// True `T_W_F` on a 20 Hz grid: (stamp, pose).
    pub trajectory: Vec<(u64, Isometry3<f64>)>,
    /// Metres per VO unit used to generate the VO.
    pub vo_scale_generation: f64,
    /// Final position drift of the VO (metric), as a fraction of the distance driven.
    pub vo_drift_fraction: f64,
}

fn stamp_of(t: f64) -> u64 {
    BASE_STAMP_NS + (t * 1e9).round() as u64
}

fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// Runs the simulation.
pub fn simulate(config: &InfraSimConfig) -> InfraSim {
    let mut building = rng(config.building_seed, 1);
    let motion = RobotMotion::new(&config.scene);
    let cameras = scene::infra_cameras(&config.scene, motion.path(), &mut building);
    let ceiling = scene::ceiling_points(&config.scene, &mut building);
    let f_camera = scene::robot_fisheye();
    let t_f_m = Isometry3::from_parts(
        Translation3::new(-0.30, 0.05, 0.08),
        UnitQuaternion::from_euler_angles(2f64.to_radians(), -1f64.to_radians(), 1.3),
    );
    let marker = MarkerSpec {
        dictionary: "DICT_4X4_50".into(),
        id: 7,
        side_m: config.marker_side_m,
    };
    let mut det_rng = rng(config.seed, 2);
    let (detections, marker_views) = cameras
        .iter()
        .map(|c| marker_detections(config, &motion, c, &t_f_m, &marker, &mut det_rng))
        .unzip();
    let n_kf = (motion.duration_s / config.keyframe_period_s) as usize + 1;
    let kf_times: Vec<f64> = (0..n_kf)
        .map(|k| k as f64 * config.keyframe_period_s)
        .collect();
    let keyframe_truth: Vec<Isometry3<f64>> = kf_times.iter().map(|&t| motion.pose(t)).collect();
    let (blobs, blob_views) = blob_detections(
        config,
        &f_camera,
        &cameras,
        &kf_times,
        &keyframe_truth,
        &mut det_rng,
    );
    let mut vo_rng = rng(config.seed, 3);
    let vo = simulate_vo(
        config,
        &f_camera,
        &kf_times,
        &keyframe_truth,
        &ceiling,
        &mut vo_rng,
    );
    let trajectory = (0..)
        .map(|i| i as f64 * 0.05)
        .take_while(|&t| t <= motion.duration_s)
        .map(|t| (stamp_of(t), motion.pose(t)))
        .collect();
    InfraSim {
        f_camera,
        marker,
        t_f_m,
        cameras,
        detections,
        marker_views,
        blobs,
        blob_views,
        vo: vo.model,
        keyframe_truth,
        trajectory,
        vo_scale_generation: vo.scale,
        vo_drift_fraction: vo.drift_fraction,
    }
}

fn marker_detections<R: Rng>(
    config: &InfraSimConfig,
    motion: &RobotMotion,
    cam: &InfraCamera,
    t_f_m: &Isometry3<f64>,
    marker: &MarkerSpec,
    rng: &mut R,
) -> (Vec<MarkerDetection>, Vec<(u64, Isometry3<f64>)>) {
    let noise = Normal::new(0.0, config.marker_noise_px).expect("finite sigma");
    let corners = marker.corners_in_marker();
    let (mut out, mut views) = (Vec::new(), Vec::new());
    let mut t = cam.phase_s;
    while t <= motion.duration_s {
        let t_c_m = cam.t_world_cam.inverse() * motion.pose(t) * t_f_m;
        if let Some(px) = image_marker(&cam.camera, &t_c_m, &corners) {
            let corners = px.map(|p| {
                let mut q = p + Vector2::new(noise.sample(rng), noise.sample(rng));
                if rng.gen_bool(config.marker_outlier_fraction) {
                    let a = rng.gen_range(0.0..std::f64::consts::TAU);
                    q += Vector2::new(a.cos(), a.sin()) * rng.gen_range(4.0..20.0);
                }
                q
            });
            out.push(MarkerDetection {
                stamp_ns: stamp_of(t),
                marker_id: marker.id,
                corners,
            });
            views.push((stamp_of(t), t_c_m));
        }
        t += cam.period_s;
    }
    (out, views)
}

/// The four corner pixels when the marker is detectable (see the module docs).
fn image_marker(
    camera: &Camera<f64>,
    t_c_m: &Isometry3<f64>,
    corners: &[Vector3<f64>; 4],
) -> Option<[Vector2<f64>; 4]> {
    let normal = t_c_m.rotation * Vector3::z();
    let sight = t_c_m.translation.vector.normalize();
    if normal.dot(&sight) > -(15f64.to_radians().sin()) {
        return None;
    }
    let mut px = [Vector2::zeros(); 4];
    for (p, c) in px.iter_mut().zip(corners) {
        let q = camera.project(&(t_c_m * nalgebra::Point3::from(*c)).coords)?;
        if !camera.in_image(&q.pixel, 3.0) {
            return None;
        }
        *p = q.pixel;
    }
    let side = (0..4)
        .map(|i| (px[i] - px[(i + 1) % 4]).norm())
        .fold(f64::MAX, f64::min);
    (side >= 10.0).then_some(px)
}

/// A keyframe's stamp and the pixels of the lights and clutter in it.
pub type KeyframeSpots = (u64, Vec<Vector2<f64>>);

fn blob_detections<R: Rng>(
    config: &InfraSimConfig,
    f: &Camera<f64>,
    cameras: &[InfraCamera],
    kf_times: &[f64],
    kf_poses: &[Isometry3<f64>],
    rng: &mut R,
) -> (Vec<Blob>, Vec<KeyframeSpots>) {
    let noise = Normal::new(0.0, config.blob_noise_px).expect("finite sigma");
    let clutter = Poisson::new(config.clutter_per_keyframe.max(1e-9)).expect("positive mean");
    let (w, h) = f.resolution;
    let centre = Vector2::new(f64::from(w) / 2.0 - 0.5, f64::from(h) / 2.0 - 0.5);
    let (mut out, mut views) = (Vec::new(), Vec::new());
    for (&t, pose) in kf_times.iter().zip(kf_poses) {
        let stamp_ns = stamp_of(t);
        let mut spots = Vec::new();
        for cam in cameras {
            let p_f = pose.inverse_transform_point(&cam.t_world_cam.translation.vector.into());
            if p_f.coords.norm() > 15.0 {
                continue;
            }
            let projected = f.project(&p_f.coords).filter(|q| f.in_image(&q.pixel, 2.0));
            spots.extend(projected.map(|q| q.pixel));
            // A CSV detection misses 5 % of the visible cameras (rendered, they are all lit).
            if !rng.gen_bool(0.95) {
                continue;
            }
            let Some(q) = f.project(&p_f.coords) else {
                continue;
            };
            let uv = q.pixel + Vector2::new(noise.sample(rng), noise.sample(rng));
            if f.in_image(&uv, 2.0) {
                out.push(Blob { stamp_ns, uv });
            }
        }
        for _ in 0..clutter.sample(rng) as usize {
            let r = 450.0 * rng.gen::<f64>().sqrt();
            let a = rng.gen_range(0.0..std::f64::consts::TAU);
            let uv = centre + Vector2::new(a.cos(), a.sin()) * r;
            out.push(Blob { stamp_ns, uv });
            spots.push(uv);
        }
        views.push((stamp_ns, spots));
    }
    (out, views)
}

struct SimulatedVo {
    model: ColmapModel,
    scale: f64,
    drift_fraction: f64,
}

/// Drifted metric keyframe poses `T_F0_Fk` (random walk on the relative motion).
fn drifted_poses<R: Rng>(
    config: &InfraSimConfig,
    truth: &[Isometry3<f64>],
    rng: &mut R,
) -> Vec<Isometry3<f64>> {
    let n = Normal::new(0.0, 1.0).expect("unit normal");
    let mut out = vec![Isometry3::identity()];
    for k in 1..truth.len() {
        let rel = truth[k - 1].inverse() * truth[k];
        let step = rel.translation.vector.norm().sqrt();
        let mut v = || Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng));
        let dr = UnitQuaternion::from_scaled_axis(v() * config.vo_rot_walk * step);
        let dt = v() * config.vo_trans_walk * step;
        let noisy = rel * Isometry3::from_parts(Translation3::from(dt), dr);
        out.push(out[k - 1] * noisy);
    }
    out
}

fn simulate_vo<R: Rng>(
    config: &InfraSimConfig,
    f: &Camera<f64>,
    kf_times: &[f64],
    truth: &[Isometry3<f64>],
    ceiling: &[Vector3<f64>],
    rng: &mut R,
) -> SimulatedVo {
    let drifted = drifted_poses(config, truth, rng);
    let scale = rng.gen_range(0.2f64.ln()..5.0f64.ln()).exp();
    let vo_from_f0 = Isometry3::from_parts(
        Translation3::new(
            rng.gen_range(-5.0..5.0),
            rng.gen_range(-5.0..5.0),
            rng.gen_range(-5.0..5.0),
        ),
        UnitQuaternion::from_scaled_axis(Vector3::new(rng.gen(), rng.gen(), rng.gen()) * 2.0),
    );
    let px = Normal::new(0.0, config.keypoint_noise_px).expect("finite sigma");
    let anchor = Normal::new(0.0, 0.01).expect("finite sigma");
    let mut images: Vec<ColmapImage> = Vec::with_capacity(truth.len());
    let mut first_seen: Vec<Option<usize>> = vec![None; ceiling.len()];
    let mut tracks: Vec<Vec<(usize, Vector2<f64>)>> = vec![Vec::new(); ceiling.len()];
    for (k, pose) in truth.iter().enumerate() {
        for (j, x) in ceiling.iter().enumerate() {
            let p_f = pose.inverse_transform_point(&(*x).into()).coords;
            if p_f.z < 0.2 * p_f.norm() || p_f.norm() > 12.0 {
                continue;
            }
            let Some(q) = f.project(&p_f) else { continue };
            let uv = q.pixel + Vector2::new(px.sample(rng), px.sample(rng));
            if f.in_image(&uv, 2.0) {
                first_seen[j].get_or_insert(k);
                tracks[j].push((k, uv));
            }
        }
    }
    let to_vo = |p_f0: Vector3<f64>| (vo_from_f0 * nalgebra::Point3::from(p_f0)).coords / scale;
    for (k, d) in drifted.iter().enumerate() {
        let t_vo_f = vo_from_f0 * d;
        let t_f_vo = Isometry3::from_parts(
            Translation3::from(-(t_vo_f.rotation.inverse() * t_vo_f.translation.vector) / scale),
            t_vo_f.rotation.inverse(),
        );
        images.push(ColmapImage {
            id: k as u32 + 1,
            stamp_ns: stamp_of(kf_times[k]),
            t_cam_world: t_f_vo,
            keypoints: Vec::new(),
        });
    }
    let mut points = Vec::new();
    for (j, track) in tracks.iter().enumerate() {
        let (Some(k0), true) = (first_seen[j], track.len() >= 2) else {
            continue;
        };
        let p_f = truth[k0].inverse_transform_point(&ceiling[j].into()).coords;
        let p_f0 = drifted[k0] * nalgebra::Point3::from(p_f);
        let noisy =
            p_f0.coords + Vector3::new(anchor.sample(rng), anchor.sample(rng), anchor.sample(rng));
        let pid = points.len();
        points.push(to_vo(noisy));
        for &(k, uv) in track {
            images[k].keypoints.push((uv, Some(pid)));
        }
    }
    let end_err = (truth[0].inverse() * truth[truth.len() - 1])
        .translation
        .vector
        - drifted[drifted.len() - 1].translation.vector;
    let distance: f64 = truth
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    SimulatedVo {
        model: ColmapModel {
            camera: *f,
            images,
            points,
        },
        scale,
        drift_fraction: end_err.norm() / distance,
    }
}
