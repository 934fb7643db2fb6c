//! Simulated corner detections for the camera-IMU tests: the simulator's true pixels plus
//! Gaussian noise, without rendering.
#![allow(dead_code)]

use msreg_estimator::CornerObservation;
use msreg_host::calibrate::camera_imu::CornerFrame;
use msreg_host::sim::CameraImuSim;
use nalgebra::Vector2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The true corners of every image with the full board in view, plus Gaussian noise.
pub fn noisy_corner_frames(sim: &CameraImuSim, sigma_px: f64, seed: u64) -> Vec<CornerFrame> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x00c0_ffee);
    let noise = Normal::new(0.0, sigma_px).expect("sigma > 0");
    let target = sim.target();
    (0..sim.frame_stamps.len())
        .filter(|&k| sim.full_board_in_view(k))
        .map(|k| CornerFrame {
            stamp_ns: sim.frame_stamps[k],
            corners: sim
                .true_corners(k)
                .iter()
                .enumerate()
                .filter_map(|(id, p)| {
                    p.map(|p| CornerObservation {
                        point_in_target: target.corner_in_target(id),
                        pixel: p + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng)),
                    })
                })
                .collect(),
        })
        .collect()
}
