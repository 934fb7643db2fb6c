//! Corner detection over a whole camera dataset (not a test): runs
//! `CameraDataset::detect` (all images, rayon on every core) and prints the wall time per
//! image, the frames detected and rejected (by reason) and, for a simulated dataset with
//! `groundtruth/corners.csv`, the RMS error against the true corners and any false
//! detection (a detection on a frame whose board is not entirely in the image).
//! Usage: `detect_dataset <dataset-dir>`.

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use anyhow::{Context, Result};
use msreg_host::dataset::{read_corners_csv, GROUNDTRUTH_CORNERS_CSV};
use msreg_host::vision::{CameraDataset, DetectorParams};

fn main() -> Result<()> {
    let dir = std::env::args()
        .nth(1)
        .context("usage: detect_dataset <dataset-dir>")?;
    let dataset = CameraDataset::open(&dir)?;
    let start = Instant::now();
    let results = dataset.detect(&DetectorParams::default(), &|_| {})?;
    let seconds = start.elapsed().as_secs_f64();
    let mut reasons: BTreeMap<String, usize> = BTreeMap::new();
    for r in &results {
        if let Err(e) = &r.corners {
            *reasons.entry(e.to_string()).or_default() += 1;
        }
    }
    let detected = results.iter().filter(|r| r.corners.is_ok()).count();
    println!(
        "{dir}: {} images in {seconds:.1} s ({:.1} ms per image, {:.1} images/s on {} threads); \
         {detected} detected",
        results.len(),
        seconds * 1e3 / results.len().max(1) as f64,
        results.len() as f64 / seconds,
        rayon::current_num_threads()
    );
    for (reason, n) in &reasons {
        println!("  rejected {n}: {reason}");
    }
    let truth_path = std::path::Path::new(&dir).join(GROUNDTRUTH_CORNERS_CSV);
    if !truth_path.is_file() {
        return Ok(());
    }
    let mut truth: HashMap<(u64, usize), (nalgebra::Vector2<f64>, bool)> = HashMap::new();
    for t in read_corners_csv(&truth_path)? {
        truth.insert((t.stamp_ns, t.corner_id), (t.pixel, t.in_image));
    }
    let n_ids = dataset.target.corner_count();
    let full = |stamp: u64| (0..n_ids).all(|id| truth.get(&(stamp, id)).is_some_and(|t| t.1));
    let (mut sum, mut n, mut worst, mut false_detections) = (0.0, 0usize, 0.0f64, 0);
    let in_view = results.iter().filter(|r| full(r.stamp_ns)).count();
    for r in &results {
        let Ok(c) = &r.corners else { continue };
        if !full(r.stamp_ns) {
            false_detections += 1;
            continue;
        }
        for (id, p) in c.ids.iter().zip(&c.pixels) {
            if let Some((t, _)) = truth.get(&(r.stamp_ns, *id)) {
                let d2 = (p - t).norm_squared();
                sum += d2;
                worst = worst.max(d2.sqrt());
                n += 1;
            }
        }
    }
    println!(
        "  truth: {in_view} frames with the full board in the image; RMS vs true corners \
         {:.4} px over {n} corners, largest error {worst:.3} px; {false_detections} false \
         detections",
        (sum / n.max(1) as f64).sqrt()
    );
    Ok(())
}
