//! Camera-IMU consistency by factor, on seeds that are NOT the acceptance seeds (3000-3009,
//! 60 s, at rest, offsets drawn in +-20 ms), at 200, 400 and 1000 Hz: one noise source at
//! a time, each run judged by its own covariance (RepErrCal, corners + 0.1 px, the filter
//! told 0.1 px and the nominal IMU densities):
//!
//! - `nominal`: IMU white noise and bias walks as simulated;
//! - `imu exact`: no IMU white noise or walk (initial biases kept): the corners' share;
//! - `accel white + corners`, `gyro white + corners`: one white noise on;
//! - `nominal, cut at peak motion`: a moving start (63 s cut at the fastest rotation of the
//!   first 20 s), as the acceptance's moving cells.
//!
//! The variants of one seed and rate share their noise draws, so they are not independent
//! samples of one another; the rates are (different samples). docs/camera_imu.md has the
//! numbers.
//!
//! `cargo test --release -p msreg-host --test camera_imu_nees_factors -- --ignored --nocapture`
//! (`MSREG_RATES=400` picks rates).

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

/// One factor setting. Corners always carry 0.1 px of noise (the filter's stated sigma,
/// `ImageNoise::Uniform`); each run is judged by its own covariance.
#[derive(Clone, Copy, Debug)]
struct Variant {
    label: &'static str,
    /// Which IMU noise is simulated: (gyro white, accel white, bias walks). The filter is
    /// always told the nominal densities.
    imu_noise: (bool, bool, bool),
    /// Cut the recording at the fastest rotation of its first 20 s (a moving start).
    cut: bool,
}

const VARIANTS: [Variant; 5] = [
    Variant {
        label: "nominal",
        imu_noise: (true, true, true),
        cut: false,
    },
    Variant {
        label: "imu exact",
        imu_noise: (false, false, false),
        cut: false,
    },
    Variant {
        label: "accel white + corners",
        imu_noise: (false, true, false),
        cut: false,
    },
    Variant {
        label: "gyro white + corners",
        imu_noise: (true, false, false),
        cut: false,
    },
    Variant {
        label: "nominal, cut at peak motion",
        imu_noise: (true, true, true),
        cut: true,
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
        duration_s: if v.cut { 63.0 } else { 60.0 },
        time_offset_s: offset,
        ..CameraImuSimConfig::default()
    };
    config.imu.rate_hz = rate_hz;
    let nominal_noise = simulate_camera_imu(&config).expect("valid").imu_noise;
    if !v.imu_noise.0 {
        config.imu.gyroscope_noise_density = 0.0;
    }
    if !v.imu_noise.1 {
        config.imu.accelerometer_noise_density = 0.0;
    }
    if !v.imu_noise.2 {
        config.imu.gyroscope_random_walk = 0.0;
        config.imu.accelerometer_random_walk = 0.0;
    }
    let sim = simulate_camera_imu(&config).expect("valid simulation config");
    let mut frames = corners::noisy_corner_frames(&sim, PIXEL_SIGMA, seed);
    let mut imu = sim.imu.clone();
    if v.cut {
        let t0 = imu[0].stamp_ns;
        let cut = imu
            .iter()
            .filter(|r| (1_000_000_000..20_000_000_000).contains(&(r.stamp_ns - t0)))
            .max_by(|a, b| a.gyro.norm().total_cmp(&b.gyro.norm()))
            .map_or(t0, |r| r.stamp_ns);
        imu.retain(|r| r.stamp_ns >= cut);
        frames.retain(|f| f.stamp_ns >= cut);
    }
    let input = CameraImuInput {
        imu: &imu,
        imu_noise: &nominal_noise,
        camera: &sim.config.camera,
        frames: &frames,
    };
    let options = CameraImuOptions {
        pixel_sigma: Some(PIXEL_SIGMA),
        image_noise: ImageNoise::Uniform,
        ..CameraImuOptions::default()
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

/// Per rate and variant: the NEES summed over seeds, its rotation and translation parts,
/// and the time-offset z^2 sum; the band is that of a consistent filter.
#[test]
#[ignore = "study, ~2 min per rate on 2 cores"]
fn nees_by_factor() {
    let seeds: Vec<u64> = (3000..3010).collect();
    let rates: Vec<f64> = std::env::var("MSREG_RATES").map_or(vec![200.0, 400.0, 1000.0], |v| {
        v.split(',')
            .map(|r| r.parse().expect("MSREG_RATES: comma-separated Hz"))
            .collect()
    });
    let (lo, hi) = chi_square_band(6.0 * seeds.len() as f64);
    // The nominal variants (at rest, moving) pooled over the rates: a consistent filter
    // keeps each pooled sum inside chi-square(6 x seeds x rates)'s 95 % band.
    let mut pooled = [0.0; 2];
    for &rate in &rates {
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
                let cov = &r.covariance;
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
                z2 += (r.offset_error_s / r.offset_sigma_s).powi(2);
            }
            match v.label {
                "nominal" => pooled[0] += total,
                "nominal, cut at peak motion" => pooled[1] += total,
                _ => {}
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
    let (lo, hi) = chi_square_band(6.0 * (seeds.len() * rates.len()) as f64);
    println!(
        "pooled nominal NEES: at rest {:.1}, moving {:.1} (band {lo:.1}-{hi:.1})",
        pooled[0], pooled[1]
    );
    for sum in pooled {
        assert!(
            (lo..=hi).contains(&sum),
            "pooled NEES {sum:.1} outside {lo:.1}-{hi:.1}"
        );
    }
}
