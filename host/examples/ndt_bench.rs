//! NDT benchmark driver for `tools/bench-ndt/run.sh` (not a test).
//!
//! - `ndt_bench prepare <out-dir> [<shared-data-dir>]`: voxel-filters (0.2 m)
//!   the real pairs of `lidar-pairs/` and a synthetic 128x1024 indoor pair,
//!   writes them as binary PCD and `pairs.txt` (one line per pair: name,
//!   target file, source file, 16 numbers of the start guess `T_target_source`,
//!   then `matrix` + 16 reference numbers or `t_yaw` + x y z yaw_deg).
//! - `ndt_bench run <out-dir> <runs>`: registers every prepared pair with
//!   msreg's NDT (`NdtParams::default()`), timing target-map build + align,
//!   and prints `RESULT msreg-NDT <pair> <median ms> <iterations> <converged>
//!   <16 numbers>` lines, plus `TIMING` lines for the synthetic raw scan.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use msreg_host::ndt::{align_scans, NdtParams};
use msreg_host::pointcloud::{read_pcd, voxel_downsample, write_pcd, PcdWriteOptions, PointCloud};
use msreg_host::sim::BoxWorld;
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};

const INPUT_VOXEL_M: f64 = 0.2;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["prepare", out] => prepare(Path::new(out), &default_data_dir()),
        ["prepare", out, data] => prepare(Path::new(out), Path::new(data)),
        ["run", out, runs] => run(Path::new(out), runs.parse().context("runs")?),
        _ => bail!("usage: ndt_bench prepare <out-dir> [<shared-data-dir>] | run <out-dir> <runs>"),
    }
}

fn default_data_dir() -> PathBuf {
    msreg_host::shared_data::root()
}

fn numbers(m: &Matrix4<f64>) -> String {
    let mut s = String::new();
    for i in 0..4 {
        for j in 0..4 {
            let _ = write!(s, " {:.9}", m[(i, j)]);
        }
    }
    s
}

fn read_matrix(path: &Path) -> Result<Matrix4<f64>> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    let values: Vec<f64> = text
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .with_context(|| path.display().to_string())?;
    if values.len() != 16 {
        bail!("{}: expected 16 numbers", path.display());
    }
    Ok(Matrix4::from_row_slice(&values))
}

fn save(out: &Path, name: &str, cloud: &PointCloud) -> Result<()> {
    let filtered = voxel_downsample(cloud, INPUT_VOXEL_M);
    write_pcd(out.join(name), &filtered, PcdWriteOptions::default())?;
    Ok(())
}

/// The synthetic pair: two 128x1024 scans of the indoor box world, 0.5 m
/// and 8 deg apart, 2 cm range jitter.
fn synthetic_pair() -> (PointCloud, PointCloud, Isometry3<f64>) {
    let world = BoxWorld::indoor();
    let pose = |t: [f64; 3], yaw_deg: f64| {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_euler_angles(0.01, -0.015, yaw_deg.to_radians()),
        )
    };
    let t_w_target = pose([0.3, -0.4, 1.2], 10.0);
    let t_w_source = pose([0.7, -0.1, 1.25], 18.0);
    let scan = |t: &Isometry3<f64>| PointCloud::from_xyz(world.scan(t, 128, 1024, 60.0, 0.02));
    (
        scan(&t_w_target),
        scan(&t_w_source),
        t_w_target.inverse() * t_w_source,
    )
}

#[allow(clippy::approx_constant)] // 0.6931 rad is PCL's tutorial guess, not ln 2
fn prepare(out: &Path, data: &Path) -> Result<()> {
    std::fs::create_dir_all(out)?;
    let pairs = data.join("lidar-pairs");
    let mut lines = String::new();
    let identity = Matrix4::identity();
    let outdoor = pairs.join("outdoor-fast-gicp");
    save(
        out,
        "outdoor_target.pcd",
        &read_pcd(outdoor.join("251370668.pcd"))?,
    )?;
    save(
        out,
        "outdoor_source.pcd",
        &read_pcd(outdoor.join("251371071.pcd"))?,
    )?;
    let reference = read_matrix(&outdoor.join("relative.txt"))?;
    let _ = writeln!(
        lines,
        "outdoor-fast-gicp outdoor_target.pcd outdoor_source.pcd{} matrix{}",
        numbers(&identity),
        numbers(&reference)
    );
    let room = pairs.join("room-pcl");
    save(
        out,
        "room_target.pcd",
        &read_pcd(room.join("room_scan1.pcd"))?,
    )?;
    save(
        out,
        "room_source.pcd",
        &read_pcd(room.join("room_scan2.pcd"))?,
    )?;
    let guess = Isometry3::from_parts(
        Translation3::new(1.79387, 0.720047, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.6931),
    );
    let _ = writeln!(
        lines,
        "room-pcl room_target.pcd room_source.pcd{} t_yaw 1.975 0.060 0.03 40.8",
        numbers(&guess.to_homogeneous())
    );
    let (target, source, truth) = synthetic_pair();
    save(out, "sim_target.pcd", &target)?;
    save(out, "sim_source.pcd", &source)?;
    let _ = writeln!(
        lines,
        "sim-128x1024 sim_target.pcd sim_source.pcd{} matrix{}",
        numbers(&identity),
        numbers(&truth.to_homogeneous())
    );
    std::fs::write(out.join("pairs.txt"), lines)?;
    Ok(())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn run(out: &Path, runs: usize) -> Result<()> {
    let params = NdtParams::default();
    let text = std::fs::read_to_string(out.join("pairs.txt"))?;
    for line in text.lines() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let [pair, target_file, source_file, ..] = fields[..] else {
            bail!("bad pairs.txt line")
        };
        let guess: Vec<f64> = fields[3..19]
            .iter()
            .map(|v| v.parse())
            .collect::<Result<_, _>>()?;
        let guess = Matrix4::from_row_slice(&guess);
        let guess = Isometry3::from_parts(
            Translation3::new(guess[(0, 3)], guess[(1, 3)], guess[(2, 3)]),
            UnitQuaternion::from_matrix(&guess.fixed_view::<3, 3>(0, 0).into_owned()),
        );
        let target = read_pcd(out.join(target_file))?;
        let source = read_pcd(out.join(source_file))?;
        let mut times = Vec::with_capacity(runs);
        let mut last = None;
        for _ in 0..runs.max(1) {
            let start = Instant::now();
            let result = align_scans(&target, &source, &guess, &params)?;
            times.push(start.elapsed().as_secs_f64() * 1e3);
            last = Some(result);
        }
        let Some(result) = last else { bail!("no run") };
        println!(
            "RESULT msreg-NDT {pair} {:.2} {} {}{}",
            median(times),
            result.iterations,
            u8::from(result.converged),
            numbers(&result.t_target_source.to_homogeneous())
        );
    }
    let (raw, _, _) = synthetic_pair();
    let times: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let start = Instant::now();
            let filtered = voxel_downsample(&raw, INPUT_VOXEL_M);
            std::hint::black_box(filtered);
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    println!(
        "TIMING voxel-filter-0.2m {} points of a raw 128x1024 scan: {:.2} ms",
        raw.len(),
        median(times)
    );
    Ok(())
}
