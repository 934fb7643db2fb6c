//! Checkerboard detection timing (not a test): median wall time per image of
//! `detect_checkerboard` on the real 640x480 OpenCV samples (`../shared/data`) and on
//! rendered 1600x1200 images (6 x 9 board, pinhole with radtan, blur 1 px, noise 3 grey
//! levels), and the camera-IMU simulator's 752x480 frames (render time, detection time,
//! parallel stream throughput against 20 Hz). Usage: `detect_bench [runs] [<shared-data-dir>]`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use msreg_estimator::camera::{radtan::RadTan, Camera, Distortion, Intrinsics, Projection};
use msreg_estimator::Pose;
use msreg_host::vision::render::{add_noise, render_checkerboard, BoardPattern, RenderSettings};
use msreg_host::vision::{detect_checkerboard, DetectorParams, GrayImage};
use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let runs: usize = args.first().map_or(Ok(5), |s| s.parse()).context("runs")?;
    let data = args
        .get(1)
        .map_or_else(msreg_host::shared_data::root, PathBuf::from);
    let params = DetectorParams::default();
    let dir = data.join("checkerboard-opencv");
    if dir.is_dir() {
        let mut times = Vec::new();
        for entry in std::fs::read_dir(&dir)? {
            let path = entry?.path();
            if path.extension().is_some_and(|e| e == "jpg") {
                let img = GrayImage::load(&path)?;
                times.push(median_ms(runs, || {
                    let _ = detect_checkerboard(&img, 6, 9, &params);
                }));
            }
        }
        report("640x480 real (checkerboard-opencv)", &mut times);
    } else {
        println!("SKIP real images: {} absent", dir.display());
    }
    let fisheye = data.join("checkerboard-fisheye");
    if fisheye.is_dir() {
        let mut times = Vec::new();
        for entry in std::fs::read_dir(&fisheye)? {
            let path = entry?.path();
            if path.extension().is_some_and(|e| e == "png") {
                let img = GrayImage::load(&path)?;
                times.push(median_ms(runs, || {
                    let _ = detect_checkerboard(&img, 6, 8, &params);
                }));
            }
        }
        report("800x503 real (checkerboard-fisheye)", &mut times);
    }
    let mut times = Vec::new();
    for img in synthetic_1600x1200()? {
        times.push(median_ms(runs, || {
            let _ = detect_checkerboard(&img, 6, 9, &params);
        }));
    }
    report("1600x1200 rendered", &mut times);
    simulated_stream(runs)?;
    Ok(())
}

/// The camera-IMU simulator's 752x480 frames (EuRoC-like camera, 6 x 7 board, blur and
/// noise): rendering time per frame, detection time per frame, and the throughput of
/// `detect_frames`-style parallel detection over a stream (both cores), against 20 Hz.
fn simulated_stream(runs: usize) -> Result<()> {
    use msreg_host::sim::camera::{simulate_camera_imu, CameraImuSimConfig};
    use rayon::prelude::*;
    for (label, config) in [
        ("sharp", CameraImuSimConfig::default()),
        (
            "blur+noise",
            CameraImuSimConfig::default().with_blur_and_noise(),
        ),
    ] {
        let sim = simulate_camera_imu(&CameraImuSimConfig {
            seed: 3,
            duration_s: 10.0,
            ..config
        })
        .map_err(|e| anyhow::anyhow!("{e}"))?;
        let frames: Vec<usize> = (0..sim.frame_stamps.len()).step_by(5).collect();
        let start = Instant::now();
        let images: Vec<GrayImage> = frames
            .iter()
            .map(|&k| GrayImage::from_luma8(&sim.image(k).to_luma8()))
            .collect();
        let render_ms = start.elapsed().as_secs_f64() * 1e3 / images.len() as f64;
        let params = DetectorParams::default();
        let (rows, cols) = (sim.config.board.rows, sim.config.board.cols);
        let mut times: Vec<f64> = images
            .iter()
            .map(|img| {
                median_ms(runs, || {
                    let _ = detect_checkerboard(img, rows, cols, &params);
                })
            })
            .collect();
        let start = Instant::now();
        let found = images
            .par_iter()
            .filter(|img| detect_checkerboard(img, rows, cols, &params).is_ok())
            .count();
        let rate = images.len() as f64 / start.elapsed().as_secs_f64();
        println!(
            "752x480 simulated ({label}): render {render_ms:.1} ms per frame (rayon); \
             parallel stream {rate:.1} frames/s ({found}/{} detected; 20 Hz needs 20)",
            images.len()
        );
        report(
            &format!("752x480 simulated ({label}) detection"),
            &mut times,
        );
    }
    Ok(())
}

fn synthetic_1600x1200() -> Result<Vec<GrayImage>> {
    let cam = Camera::new(
        Projection::Pinhole,
        Intrinsics {
            fu: 1100.0,
            fv: 1100.0,
            cu: 799.5,
            cv: 599.5,
        },
        Distortion::RadTan(RadTan {
            k1: -0.1,
            k2: 0.03,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        }),
        (1600, 1200),
    )
    .map_err(|e| anyhow::anyhow!("camera: {e:?}"))?;
    let board = BoardPattern {
        rows: 6,
        cols: 9,
        row_spacing_m: 0.04,
        col_spacing_m: 0.04,
        margin_m: 0.03,
    };
    let centre = Vector3::new(0.1, 0.16, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    Ok([
        (0.0, 0.0, 0.1, 0.7),
        (0.4, -0.3, 0.8, 0.9),
        (-0.3, 0.4, 2.9, 1.2),
    ]
    .iter()
    .map(|&(rx, ry, rz, dist)| {
        let r = UnitQuaternion::from_euler_angles(rx, ry, rz)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let pose = Pose::new(r, Vector3::new(0.0, 0.0, dist) - r * centre);
        let mut img =
            render_checkerboard(&cam, &pose, &board, &RenderSettings::default()).gaussian_blur(1.0);
        add_noise(&mut img, 3.0, &mut rng);
        img
    })
    .collect())
}

fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn report(what: &str, times: &mut [f64]) {
    if times.is_empty() {
        return;
    }
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!(
        "{what}: {} images, per image median {:.1} ms, mean {mean:.1} ms, max {:.1} ms",
        times.len(),
        times[times.len() / 2],
        times[times.len() - 1]
    );
}
