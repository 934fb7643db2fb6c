//! The dataset layout of an intrinsics recording (module docs of [`super`]).

use std::sync::atomic::{AtomicUsize, Ordering};

use serde_yaml::{Mapping, Value};

use super::*;

/// The sensor folder of camera `n`.
pub fn camera_dir(n: usize) -> String {
    format!("cam{n}")
}

/// `groundtruth/camN/corners.csv`: the true corners of camera `n` (relative path).
pub fn groundtruth_corners_csv(n: usize) -> String {
    format!("groundtruth/cam{n}/corners.csv")
}

fn numbers(values: &[f64]) -> Value {
    Value::Sequence(values.iter().map(|&v| Value::from(v)).collect())
}

fn matrix(t: &Isometry3<f64>) -> Value {
    let m = t.to_homogeneous();
    Value::Sequence(
        (0..4)
            .map(|r| numbers(&[m[(r, 0)], m[(r, 1)], m[(r, 2)], m[(r, 3)]]))
            .collect(),
    )
}

fn resolution(camera: &SimCamera) -> Value {
    Value::Sequence(
        camera
            .resolution
            .iter()
            .map(|&v| Value::from(u64::from(v)))
            .collect(),
    )
}

impl CamerasSim {
    /// `camN/camera.yaml`: what a user knows before calibrating (model, distortion model,
    /// resolution).
    pub fn camera_yaml(&self, n: usize) -> String {
        let c = &self.cameras[n];
        format!(
            "# known before calibration\ncamera_model: {}\ndistortion_model: {}\n\
             resolution: [{}, {}]\n",
            c.kalibr_model(),
            c.kalibr_distortion(),
            c.resolution[0],
            c.resolution[1]
        )
    }

    /// `groundtruth/extrinsics.yaml`: one `camN` section per camera with Kalibr's camchain
    /// keys (`camera_model`, `intrinsics`, `distortion_model`, `distortion_coeffs`,
    /// `resolution`, and `T_cn_cnm1` for N >= 1).
    pub fn groundtruth_yaml(&self) -> String {
        let mut root = Mapping::new();
        for (n, c) in self.cameras.iter().enumerate() {
            let mut s = Mapping::new();
            s.insert("camera_model".into(), c.kalibr_model().into());
            s.insert("intrinsics".into(), numbers(&c.kalibr_intrinsics()));
            s.insert("distortion_model".into(), c.kalibr_distortion().into());
            s.insert(
                "distortion_coeffs".into(),
                numbers(&c.kalibr_distortion_coeffs()),
            );
            s.insert("resolution".into(), resolution(c));
            if n >= 1 {
                s.insert("T_cn_cnm1".into(), matrix(&self.t_cn_cnm1(n)));
            }
            root.insert(camera_dir(n).into(), Value::Mapping(s));
        }
        serde_yaml::to_string(&Value::Mapping(root)).unwrap_or_default()
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        let names: Vec<String> = (0..c.cameras).map(camera_dir).collect();
        DatasetYaml {
            description: format!(
                "msreg simulator: intrinsics, seed {}, {} camera(s) {:?}, {} frames at {} Hz, \
                 camN triggered N x {} s after cam0, {:?}, exposure {:?} s, noise {} grey levels",
                c.seed,
                c.cameras,
                c.model,
                c.frames,
                c.rate_hz,
                c.unsynced_s,
                c.target.kalibr(),
                c.exposure_s,
                c.noise_sigma
            ),
            rates_hz: names.iter().map(|n| (n.clone(), c.rate_hz)).collect(),
            sensors: names,
        }
    }

    /// The true corners of camera `n` as `groundtruth/camN/corners.csv` rows.
    pub fn corner_truth(&self, n: usize) -> Vec<CornerTruth> {
        let cam = &self.cameras[n];
        (0..self.config.frames)
            .into_par_iter()
            .flat_map_iter(|k| {
                let stamp_ns = self.stamp_ns(n, k);
                self.true_corners(n, k)
                    .into_iter()
                    .enumerate()
                    .filter_map(move |(corner_id, p)| {
                        p.map(|pixel| CornerTruth {
                            stamp_ns,
                            corner_id,
                            pixel,
                            in_image: cam.in_image(&pixel),
                        })
                    })
            })
            .collect()
    }

    /// `groundtruth/trajectory.csv` rows: the pose of cam0 in `G` (the target frame) at
    /// cam0's stamps; velocity by central differences of the exact motion over 1 ms.
    fn trajectory(&self) -> Vec<GroundTruthRecord> {
        (0..self.config.frames)
            .map(|k| {
                let t = self.capture_time(0, k);
                let pose = |t: f64| self.t_cam_target(0, t).inverse();
                let h = 5e-4;
                let velocity =
                    (pose(t + h).translation.vector - pose(t - h).translation.vector) / (2.0 * h);
                let p = pose(t);
                GroundTruthRecord {
                    stamp_ns: self.stamp_ns(0, k),
                    position: p.translation.vector,
                    rotation: p.rotation,
                    velocity,
                    gyro_bias: Vector3::zeros(),
                    accel_bias: Vector3::zeros(),
                }
            })
            .collect()
    }

    /// Writes the dataset under `dir` (created if needed), rendering the images in
    /// parallel; `progress` gets the fraction of images written.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let n_cams = self.config.cameras;
        let mut subs: Vec<String> = vec!["groundtruth".into()];
        for n in 0..n_cams {
            subs.push(format!("cam{n}/data"));
            subs.push(format!("groundtruth/cam{n}"));
        }
        create_dirs(dir, &subs.iter().map(String::as_str).collect::<Vec<_>>())?;
        let text = |relative: &str, content: &str| write_text(&dir.join(relative), content);
        self.metadata().write(dir.join(DATASET_YAML))?;
        let target_yaml = match self.config.target.kalibr() {
            Target::AprilGrid(t) => aprilgrid_yaml_string(&t),
            Target::Checkerboard(t) => checkerboard_yaml_string(&t),
            Target::Board(_) => String::new(),
        };
        text(TARGET_YAML, &target_yaml)?;
        text(GROUNDTRUTH_EXTRINSICS_YAML, &self.groundtruth_yaml())?;
        let trajectory = self.trajectory();
        write_groundtruth_csv(dir.join(GROUNDTRUTH_TRAJECTORY_CSV), &trajectory)?;
        let identity: Vec<PoseRecord> = trajectory
            .iter()
            .map(|r| PoseRecord::from_isometry(r.stamp_ns, &Isometry3::identity()))
            .collect();
        write_pose_csv(dir.join(GROUNDTRUTH_TARGET_POSES_CSV), &identity)?;
        for n in 0..n_cams {
            text(&format!("cam{n}/camera.yaml"), &self.camera_yaml(n))?;
            write_corners_csv(dir.join(groundtruth_corners_csv(n)), &self.corner_truth(n))?;
        }
        self.write_images(dir, progress)
    }

    fn write_images(
        &self,
        dir: &Path,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<(), DatasetError> {
        let (n_cams, frames) = (self.config.cameras, self.config.frames);
        let listing: Vec<Vec<CameraFrame>> = (0..n_cams)
            .map(|n| {
                (0..frames)
                    .map(|k| {
                        let stamp_ns = self.stamp_ns(n, k);
                        CameraFrame {
                            stamp_ns,
                            path: dir.join(format!("cam{n}/data/{stamp_ns}.png")),
                        }
                    })
                    .collect()
            })
            .collect();
        let done = AtomicUsize::new(0);
        let total = (n_cams * frames) as f64;
        (0..n_cams * frames).into_par_iter().try_for_each(|i| {
            let (n, k) = (i / frames, i % frames);
            write_png(&listing[n][k].path, &self.image(n, k))?;
            let count = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(count as f64 / total);
            Ok::<(), DatasetError>(())
        })?;
        for (n, frames) in listing.iter().enumerate() {
            write_camera_csv(dir.join(format!("cam{n}/data.csv")), frames)?;
        }
        Ok(())
    }
}
