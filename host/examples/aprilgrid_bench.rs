//! AprilGrid detection benchmark (not a test): the camera-IMU simulator's 752x480 frames
//! with its Kalibr AprilGrid (6 x 5 tag36h11 tags of 5 cm, blur and noise), every 5th frame
//! of 10 s, quantised to 8 bits as the PNGs are. Prints the frames detected, the corners
//! found of those visible (whole tag 3 px inside the image), their error against the true
//! projections, and the median / 90th-percentile wall time of `detect_aprilgrid` per frame
//! (one thread, median of `runs` runs per frame).
//! Usage: `aprilgrid_bench [runs] [seed] [refine_window_bits]`.

use std::time::Instant;

use anyhow::{Context, Result};
use msreg_host::camera_yaml::Target;
use msreg_host::sim::camera::{simulate_camera_imu, CameraImuSimConfig};
use msreg_host::vision::aprilgrid::{detect_aprilgrid, AprilGridParams};
use msreg_host::vision::GrayImage;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let runs: usize = args.first().map_or(Ok(5), |s| s.parse()).context("runs")?;
    let seed: u64 = args.get(1).map_or(Ok(3), |s| s.parse()).context("seed")?;
    let mut params = AprilGridParams::default();
    if let Some(w) = args.get(2) {
        params.refine_window_bits = w.parse().context("refine_window_bits")?;
    }
    let sim = simulate_camera_imu(&CameraImuSimConfig {
        seed,
        duration_s: 10.0,
        aprilgrid: Some(CameraImuSimConfig::default_aprilgrid()),
        ..CameraImuSimConfig::default().with_blur_and_noise()
    })
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let Target::AprilGrid(target) = sim.printed_target() else {
        anyhow::bail!("the simulator printed no aprilgrid");
    };
    let camera = &sim.config.camera;
    let frames: Vec<usize> = (0..sim.frame_stamps.len()).step_by(5).collect();
    let (mut errors, mut times) = (Vec::new(), Vec::new());
    let (mut visible, mut found, mut detected) = (0, 0, 0);
    for &k in &frames {
        let image = GrayImage::from_luma8(&sim.image(k).to_luma8());
        let truth = sim.true_corners(k);
        let whole = |id: usize| {
            (4 * (id / 4)..4 * (id / 4) + 4)
                .all(|j| truth[j].is_some_and(|p| camera.in_image(&p, 3.0)))
        };
        visible += (0..truth.len()).filter(|&id| whole(id)).count();
        let mut samples = Vec::with_capacity(runs);
        let mut result = None;
        for _ in 0..runs.max(1) {
            let start = Instant::now();
            result = Some(detect_aprilgrid(&image, &target, &params));
            samples.push(start.elapsed().as_secs_f64() * 1e3);
        }
        times.push(median(&mut samples));
        if let Some(Ok(d)) = result {
            detected += 1;
            for (&id, pixel) in d.ids.iter().zip(&d.pixels) {
                let t = truth[id].context("a detected corner with no true projection")?;
                errors.push((pixel - t).norm());
                found += usize::from(whole(id));
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    times.sort_by(f64::total_cmp);
    println!(
        "aprilgrid 752x480 simulated (seed {seed}, 6x5 tags, blur+noise, refine window {} \
         bits): {detected}/{} frames detected, {found}/{visible} visible corners found, \
         error median {:.3} px, max {:.3} px; detection median {:.1} ms, p90 {:.1} ms per \
         frame (1 thread, {runs} runs)",
        params.refine_window_bits,
        frames.len(),
        errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN),
        errors.last().copied().unwrap_or(f64::NAN),
        times[times.len() / 2],
        times[times.len() * 9 / 10],
    );
    Ok(())
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
