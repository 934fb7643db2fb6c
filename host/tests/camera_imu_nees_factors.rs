//! Which factor inflates the camera-IMU NEES at 200-400 Hz (issue 11 follow-up): one factor
//! changed at a time on seeds that are NOT the acceptance seeds (3000-3009), 60 s, at rest.
//!
//! Every variant runs RepErrCal with one fixed corner noise (0.1 px, `ImageNoise::Uniform`),
//! so the filter's covariance depends on the trajectory only, not on the noise draws, and
//! the error of a noise-free run can be judged by the covariance of the noisy one:
//!
//! - `nominal`: IMU noise and bias walk as simulated, corners + 0.1 px;
//! - `imu exact`: no IMU white noise or bias walk (initial biases kept), corners + 0.1 px;
//! - `deterministic`: neither; its error against the nominal covariance is the error no noise
//!   explains (discretisation, interpolation, initialisation);
//! - `deterministic, images on samples`: the same with `t_d = 0`, so every image falls on an
//!   IMU sample and no reading is interpolated at an image instant.
//!
//! `cargo test --release -p msreg --test camera_imu_nees_factors -- --ignored --nocapture`
//! (`MSREG_RATES=200,1000` picks rates).

#[path = "support/common.rs"]
mod common;
#[path = "support/corners.rs"]
mod corners;

use common::{chi_square_band, extrinsic_error, par_map};
use msreg_host::calibrate::camera_imu::{self, CameraImuInput, CameraImuOptions, ImageNoise};
use msreg_host::sim::{simulate_camera_imu, CameraImuSimConfig};
use nalgebra::{Matrix6, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Corner noise of the noisy variants and the filter's stated corner noise, px.
const PIXEL_SIGMA: f64 = 0.1;

/// One factor setting.
#[derive(Clone, Copy, Debug)]
struct Variant {
    label: &'static str,
    imu_noise: bool,
    corner_noise: bool,
    offset: bool,
    /// The pipeline's default corner weighting (per-image noise from the PnP residuals,
    /// robust reweighting), judged by its own covariance.
    per_image: bool,
}

const VARIANTS: [Variant; 6] = [
    Variant {
        label: "nominal",
        imu_noise: true,
        corner_noise: true,
        offset: true,
        per_image: false,
    },
    Variant {
        label: "imu exact",
        imu_noise: false,
        corner_noise: true,
        offset: true,
        per_image: false,
    },
    Variant {
        label: "deterministic",
        imu_noise: false,
        corner_noise: false,
        offset: true,
        per_image: false,
    },
    Variant {
        label: "deterministic, images on samples",
        imu_noise: false,
        corner_noise: false,
        offset: false,
        per_image: false,
    },
    Variant {
        label: "nominal, per-image corner noise",
        imu_noise: true,
        corner_noise: true,
        offset: true,
        per_image: true,
    },
    Variant {
        label: "imu exact, per-image corner noise",
        imu_noise: false,
        corner_noise: true,
        offset: true,
        per_image: true,
    },
];

/// Extrinsic error `[dtheta; dp]`, its covariance, and the time-offset error and sigma, s.
struct Run {
    error: Vector6<f64>,
    covariance: Matrix6<f64>,
    offset_error_s: f64,
    offset_sigma_s: f64,
}

fn run(seed: u64, rate_hz: f64, v: Variant) -> Run {
    let offset = ChaCha8Rng::seed_from_u64(seed ^ 0x7d_0ff5e7).gen_range(-0.020..0.020);
    let mut config = CameraImuSimConfig {
        seed,
        duration_s: 60.0,
        time_offset_s: if v.offset { offset } else { 0.0 },
        ..CameraImuSimConfig::default()
    };
    config.imu.rate_hz = rate_hz;
    let nominal_noise = simulate_camera_imu(&config).expect("valid").imu_noise;
    if !v.imu_noise {
        config.imu.gyroscope_noise_density = 0.0;
        config.imu.accelerometer_noise_density = 0.0;
        config.imu.gyroscope_random_walk = 0.0;
        config.imu.accelerometer_random_walk = 0.0;
    }
    let sim = simulate_camera_imu(&config).expect("valid simulation config");
    let sigma = if v.corner_noise { PIXEL_SIGMA } else { 1e-12 };
    let frames = corners::noisy_corner_frames(&sim, sigma, seed);
    let input = CameraImuInput {
        imu: &sim.imu,
        imu_noise: &nominal_noise,
        camera: &sim.config.camera,
        frames: &frames,
    };
    let options = if v.per_image {
        CameraImuOptions::default()
    } else {
        CameraImuOptions {
            pixel_sigma: Some(PIXEL_SIGMA),
            image_noise: ImageNoise::Uniform,
            ..CameraImuOptions::default()
        }
    };
    let c = camera_imu::calibrate::<f64>(&input, &options, &mut |_| {}).expect("runs");
    Run {
        error: extrinsic_error(&c.t_imu_sensor, &sim.t_cam_imu.inverse()),
        covariance: c.covariance,
        offset_error_s: c.time_offset_s - sim.config.time_offset_s,
        offset_sigma_s: c.time_offset_sigma_s,
    }
}

fn nees(e: &Vector6<f64>, cov: &Matrix6<f64>) -> f64 {
    cov.try_inverse()
        .map_or(f64::NAN, |info| e.dot(&(info * e)))
}

/// Per variant: the NEES summed over seeds (each run's error against the NOMINAL run's
/// covariance), the rotation and translation parts of it, and the time-offset z^2 sum.
#[test]
#[ignore = "study, ~2 min per rate on 2 cores"]
fn nees_by_factor() {
    let seeds: Vec<u64> = (3000..3010).collect();
    let rates: Vec<f64> = std::env::var("MSREG_RATES").map_or(vec![200.0, 1000.0], |v| {
        v.split(',')
            .map(|r| r.parse().expect("MSREG_RATES: comma-separated Hz"))
            .collect()
    });
    let (lo, hi) = chi_square_band(6.0 * seeds.len() as f64);
    for rate in rates {
        let runs: Vec<Vec<Run>> = par_map(&seeds, |seed| {
            VARIANTS.iter().map(|v| run(seed, rate, *v)).collect()
        });
        println!("{rate} Hz, seeds 3000-3009 (NEES band of the sum {lo:.1}-{hi:.1}):");
        for (i, v) in VARIANTS.iter().enumerate() {
            let mut total = 0.0;
            let mut rot = 0.0;
            let mut trans = 0.0;
            let mut z2 = 0.0;
            let mut per_seed = Vec::new();
            for seed_runs in &runs {
                let r = &seed_runs[i];
                let judge = if v.per_image { r } else { &seed_runs[0] };
                let cov = &judge.covariance;
                let n = nees(&r.error, cov);
                total += n;
                per_seed.push(n);
                let block = |k: usize| {
                    let c = cov.fixed_view::<3, 3>(k, k).clone_owned();
                    let e = r.error.fixed_rows::<3>(k).clone_owned();
                    c.try_inverse().map_or(f64::NAN, |info| e.dot(&(info * e)))
                };
                rot += block(0);
                trans += block(3);
                z2 += (r.offset_error_s / judge.offset_sigma_s).powi(2);
            }
            let seeds_txt: Vec<String> = per_seed.iter().map(|n| format!("{n:.1}")).collect();
            println!(
                "  {:<34} NEES sum {total:6.1} (rotation {rot:6.1}, translation {trans:6.1}), \
                 t_d z^2 sum {z2:6.1}; per seed [{}]",
                v.label,
                seeds_txt.join(", ")
            );
        }
    }
}
