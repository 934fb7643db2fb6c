//! Several cameras on the one hand-held rig (`msreg simulate camera-imu --cameras N`): the
//! motion, the IMU record and the target of [`simulate_camera_imu`] (which keeps the board in
//! camera 0's view), seen by each camera `n` through its own mounting `T_cn_c0` on the rig and
//! its own time offset. Every camera is rendered from the trajectory alone, exactly as camera
//! 0 is ([`CameraImuSim::with_camera`]).
//!
//! Ground truth: every `camN.T_cam_imu` and `timeshift_cam_imu`, and for `N >= 1` the chain
//! `camN.T_cn_cnm1`; each camera's true corners (`groundtruth/corners.csv` for cam0,
//! `groundtruth/corners_camN.csv` for the others).

use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::{simulate_camera_imu, CameraImuSim, CameraImuSimConfig};
use crate::dataset::{
    write_corners_csv, CalibrationResult, DatasetError, DatasetYaml, ExtrinsicEstimate,
    SectionName, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML,
};
use crate::sim::config::SimError;

/// Spacing of the cameras along camera 0's x axis in [`CameraRigSimConfig::row`], m: a
/// stereo pair's baseline.
pub const ROW_BASELINE_M: f64 = 0.11;
/// Each further camera's time offset after the previous one's in
/// [`CameraRigSimConfig::row`], s.
pub const ROW_TIME_OFFSET_STEP_S: f64 = 0.003;

/// Camera `n >= 1` of the rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigCamera {
    /// Its mounting against camera 0: `p_camN = T_cn_c0 p_cam0`.
    pub t_cn_c0: Isometry3<f64>,
    /// Its time offset `t_d`, s (stamp + `t_d` = IMU time).
    pub time_offset_s: f64,
}

/// The rig: camera 0 and its recording as [`CameraImuSimConfig`] describes them, and the
/// other cameras (the same lens model as camera 0).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraRigSimConfig {
    /// Camera 0, the motion, the IMU and the target.
    pub base: CameraImuSimConfig,
    /// Cameras 1, 2, ...
    pub others: Vec<RigCamera>,
}

impl CameraRigSimConfig {
    /// `cameras` cameras in a row along camera 0's x axis, [`ROW_BASELINE_M`] apart (a stereo
    /// pair for two), each turned 4 deg about its y axis towards the row's start so the
    /// board stays near the middle of every view, with 0.3 deg of roll and a few mm off the
    /// row, as a real bracket has; camera `n`'s time offset is camera 0's plus `n` times
    /// [`ROW_TIME_OFFSET_STEP_S`].
    pub fn row(base: CameraImuSimConfig, cameras: usize) -> Self {
        let others = (1..cameras.max(1))
            .map(|n| {
                let k = n as f64;
                let rotation = UnitQuaternion::from_euler_angles(
                    0.3_f64.to_radians() * k,
                    4.0_f64.to_radians() * k,
                    -0.2_f64.to_radians() * k,
                );
                let centre = Vector3::new(ROW_BASELINE_M * k, 0.002 * k, -0.003 * k);
                RigCamera {
                    t_cn_c0: Isometry3::from_parts(
                        Translation3::from(-(rotation * centre)),
                        rotation,
                    ),
                    time_offset_s: base.time_offset_s + ROW_TIME_OFFSET_STEP_S * k,
                }
            })
            .collect();
        Self { base, others }
    }
}

/// A simulated camera rig recording: `cameras[n]` is camera `n` (all share the motion, the
/// IMU record and the target).
#[derive(Debug, Clone)]
pub struct CameraRigSim {
    /// Every camera's recording.
    pub cameras: Vec<CameraImuSim>,
}

/// Simulates the rig described by `config`.
pub fn simulate_camera_rig(config: &CameraRigSimConfig) -> Result<CameraRigSim, SimError> {
    let base = simulate_camera_imu(&config.base)?;
    let mut cameras = Vec::with_capacity(config.others.len() + 1);
    for (n, other) in config.others.iter().enumerate() {
        let seed = config.base.seed ^ ((n as u64 + 1) << 40);
        cameras.push(base.with_camera(
            config.base.camera,
            other.t_cn_c0 * base.t_cam_imu,
            other.time_offset_s,
            seed,
        )?);
    }
    cameras.insert(0, base);
    Ok(CameraRigSim { cameras })
}

impl CameraRigSim {
    /// The true extrinsics in result-file form (sigmas zero): every `camN.T_cam_imu` with its
    /// time offset, and `camN.T_cn_cnm1` for `N >= 1`.
    pub fn extrinsics(&self) -> CalibrationResult {
        let mut truth = CalibrationResult::new();
        for (n, c) in self.cameras.iter().enumerate() {
            let name = SectionName::cam(n as u16);
            truth.set_extrinsic(
                name,
                ExtrinsicEstimate::exact(c.t_cam_imu, c.config.time_offset_s),
            );
            if n >= 1 {
                let previous = &self.cameras[n - 1];
                truth.section_mut(name).camera_chain = Some(ExtrinsicEstimate::exact(
                    c.t_cam_imu * previous.t_cam_imu.inverse(),
                    0.0,
                ));
            }
        }
        truth
    }

    /// `dataset.yaml` contents: camera 0's, with every camera listed.
    pub fn metadata(&self) -> DatasetYaml {
        let mut meta = self.cameras[0].metadata();
        for n in 1..self.cameras.len() {
            meta.sensors.push(format!("cam{n}"));
            meta.rates_hz
                .insert(format!("cam{n}"), self.cameras[n].config.rate_hz);
        }
        meta.description = format!(
            "{}; {} cameras in one rig (time offsets {:?} s)",
            meta.description,
            self.cameras.len(),
            self.cameras
                .iter()
                .map(|c| c.config.time_offset_s)
                .collect::<Vec<_>>()
        );
        meta
    }

    /// Writes the dataset under `dir`: camera 0's recording as [`CameraImuSim::write`] does,
    /// every other camera's folder `camN/`, its true corners, and the rig's ground truth and
    /// `dataset.yaml`; `progress` gets the fraction of images written.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let count = self.cameras.len() as f64;
        self.cameras[0].write(dir, &|f| progress(f / count))?;
        for (n, camera) in self.cameras.iter().enumerate().skip(1) {
            let name = format!("cam{n}");
            camera.write_camera(dir, &name, &|f| progress((n as f64 + f) / count))?;
            write_corners_csv(
                dir.join(format!("groundtruth/corners_{name}.csv")),
                &camera.corner_truth(),
            )?;
        }
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        self.metadata().write(dir.join(DATASET_YAML))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stereo_row_sees_the_board_and_chains_its_truth() -> Result<(), SimError> {
        // Given a 20 s two-camera row
        let config = CameraRigSimConfig::row(
            CameraImuSimConfig {
                seed: 3,
                duration_s: 20.0,
                time_offset_s: -0.004,
                ..CameraImuSimConfig::default()
            },
            2,
        );
        let rig = simulate_camera_rig(&config)?;
        // Then camera 1 has its own offset and the 11 cm baseline
        let (c0, c1) = (&rig.cameras[0], &rig.cameras[1]);
        assert!((c1.config.time_offset_s + 0.001).abs() < 1e-15);
        let t_c1_c0 = c1.t_cam_imu * c0.t_cam_imu.inverse();
        let baseline = t_c1_c0.inverse().translation.vector.norm();
        assert!((baseline - 0.110_06).abs() < 1e-4, "{baseline}");
        // and the ground truth chains it
        let truth = rig.extrinsics();
        let chain = truth
            .section(&SectionName::cam(1))
            .and_then(|s| s.camera_chain)
            .map(|c| c.transform);
        assert_eq!(chain, Some(t_c1_c0));
        // and both cameras see the full board in nearly every frame (measured: seed 3, all
        // 399 frames of each)
        for c in [c0, c1] {
            let n = c.frame_stamps.len();
            let in_view = (0..n).filter(|&k| c.full_board_in_view(k)).count();
            println!("{in_view}/{n} frames with the full board");
            assert!(in_view as f64 >= 0.9 * n as f64, "{in_view}/{n}");
        }
        Ok(())
    }
}
