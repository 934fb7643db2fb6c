//! NDT accuracy on the real LiDAR scan pairs of `../shared/data/lidar-pairs`
//! (README there): outdoor-fast-gicp against `relative.txt`, room-pcl from
//! PCL's tutorial guess against the consensus of four registrations. Both
//! clouds are voxel-filtered at 0.2 m, as in `tools/bench-ndt`. Skips with a
//! notice when `../shared` is absent (a fresh clone).

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use msreg_host::ndt::{align_scans, NdtParams, NdtResult};
use msreg_host::pointcloud::{read_pcd, voxel_downsample, PointCloud};
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};

const INPUT_VOXEL_M: f64 = 0.2;

fn pairs_dir() -> Option<PathBuf> {
    msreg_host::shared_data::dir_or_skip("lidar-pairs")
}

fn load(path: &Path) -> PointCloud {
    voxel_downsample(&read_pcd(path).unwrap(), INPUT_VOXEL_M)
}

fn register(target: &Path, source: &Path, guess: &Isometry3<f64>) -> NdtResult {
    let (target, source) = (load(target), load(source));
    let start = Instant::now();
    let result = align_scans(&target, &source, guess, &NdtParams::default()).unwrap();
    println!(
        "{} <- {} points: {:.1} ms, {} iterations, fitness {:.3}, converged {}, degenerate {:?}",
        target.len(),
        source.len(),
        start.elapsed().as_secs_f64() * 1e3,
        result.iterations,
        result.fitness,
        result.converged,
        result.degenerate,
    );
    result
}

fn read_matrix(path: &Path) -> Isometry3<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let values: Vec<f64> = text
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let m = Matrix4::from_row_slice(&values);
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let rotation = UnitQuaternion::from_matrix(&r);
    Isometry3::from_parts(
        Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()),
        rotation,
    )
}

#[test]
fn outdoor_pair_matches_the_reference_from_identity() {
    let Some(dir) = pairs_dir() else { return };
    let dir = dir.join("outdoor-fast-gicp");
    // Given the outdoor pair and its reference T_target_source
    let reference = read_matrix(&dir.join("relative.txt"));
    // When registered from identity (0.49 m / 0.6 deg away)
    let result = register(
        &dir.join("251370668.pcd"),
        &dir.join("251371071.pcd"),
        &Isometry3::identity(),
    );
    // Then it lands within the reference spread
    let d = reference.inverse() * result.t_target_source;
    let (dt, dr) = (d.translation.vector.norm(), d.rotation.angle().to_degrees());
    println!("outdoor: {:.4} m, {:.4} deg from relative.txt", dt, dr);
    assert!(dt < 0.03 && dr < 0.3, "{dt} m {dr} deg");
    assert!(result.converged && result.degenerate.is_none());
}

#[test]
#[allow(clippy::approx_constant)] // 0.6931 rad is the tutorial's guess, not ln 2
fn room_pair_reaches_the_consensus_from_the_tutorial_guess() {
    let Some(dir) = pairs_dir() else { return };
    let dir = dir.join("room-pcl");
    // Given PCL's NDT-tutorial guess for scan2 into scan1
    let guess = Isometry3::from_parts(
        Translation3::new(1.79387, 0.720047, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.6931),
    );
    // When registered
    let result = register(
        &dir.join("room_scan1.pcd"),
        &dir.join("room_scan2.pcd"),
        &guess,
    );
    // Then it reaches the consensus t = (1.975, 0.060, 0.03) m, yaw 40.8 deg
    let t = result.t_target_source.translation.vector;
    let (roll, pitch, yaw) = result.t_target_source.rotation.euler_angles();
    println!(
        "room: t = ({:.4}, {:.4}, {:.4}) m, rpy = ({:.3}, {:.3}, {:.3}) deg",
        t.x,
        t.y,
        t.z,
        roll.to_degrees(),
        pitch.to_degrees(),
        yaw.to_degrees()
    );
    assert!((t - Vector3::new(1.975, 0.060, 0.03)).norm() < 0.02, "{t}");
    assert!(
        (yaw.to_degrees() - 40.8).abs() < 0.3,
        "yaw {}",
        yaw.to_degrees()
    );
    assert!(result.converged && result.degenerate.is_none());
}
