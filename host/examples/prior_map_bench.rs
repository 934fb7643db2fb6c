//! Benchmark of the prior-map MI stage (issue 15, speed acceptance): the production
//! `msreg calibrate prior-map` grid over (x, y, z, yaw) and the 6-DoF refinement
//! (`msreg_host::mi::prior_map::{grid_stage, refine_stage}`) on a simulated intersection
//! with about 100k map points in view, from the true pose moved by `OFFSET`. Prints a
//! markdown table (wall and CPU time, evaluations, MI at the optimum, pose found) and
//! writes the grid's exact problem (the same points, values, blurred image, camera, start
//! and lattice) to `<dir>` (default /tmp/prior_map_bench) for the NumPy anchor
//! `tools/mi_grid_numpy.py`.
//!
//! `cargo run --release -p msreg-host --example prior_map_bench [-- <dir> [seed] [map points]]`

use std::io::Write;
use std::time::Instant;

use msreg_estimator::camera::{Distortion, Projection};
use msreg_host::dataset::read_t_world_cam;
use msreg_host::mi::prior_map::input::read_input;
use msreg_host::mi::prior_map::{
    grid_pose, grid_scene, grid_stage, mi_scene, refine_stage, yaw_error, RegisterOptions,
};
use msreg_host::mi::scene::{equalize, MiScene};
use msreg_host::sim::prior_map::{simulate_prior_map, PriorMapSimConfig};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Start = truth moved by x, y, z (m) in W and yaw (deg): inside the grid's +-0.5, 0.5,
/// 0.3 m, 2 deg, off its lattice.
const OFFSET: [f64; 4] = [0.31, -0.22, 0.13, 1.3];

/// Process CPU time (user + system, s) from /proc/self/stat (clock ticks of 10 ms).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // After "pid (comm)": state, ppid, ... ; utime and stime are the 12th and 13th.
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|s| s.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}

/// Runs `f`, returning its value with wall and CPU seconds.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let (wall, cpu) = (Instant::now(), cpu_seconds());
    let v = f();
    (v, wall.elapsed().as_secs_f64(), cpu_seconds() - cpu)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().unwrap_or_else(|| "/tmp/prior_map_bench".into());
    let seed: u64 = args.next().map_or(Ok(31), |s| s.parse())?;
    let map_points: usize = args.next().map_or(Ok(212_000), |s| s.parse())?;
    // The dataset is simulated once per directory and reused (delete it to re-simulate).
    let dataset = std::path::PathBuf::from(format!("{dir}/dataset-s{seed}-n{map_points}"));
    let truth_file = dataset.join("groundtruth/extrinsics.yaml");
    if !truth_file.exists() {
        let sim = simulate_prior_map(&PriorMapSimConfig {
            seed,
            map_points,
            ..PriorMapSimConfig::default()
        });
        sim.write(&dataset)?;
    }
    let input = read_input(&dataset)?;
    let truth = read_t_world_cam(&truth_file).map_err(|e| e.to_string())?;
    let start = Isometry3::from_parts(
        Translation3::from(
            truth.translation.vector + Vector3::new(OFFSET[0], OFFSET[1], OFFSET[2]),
        ),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), OFFSET[3].to_radians())
            * truth.rotation,
    );
    let mut options = RegisterOptions::default();
    // Development only: PMB_GRID_POINTS, PMB_SUB1, PMB_HESS_EVERY override the defaults.
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<usize>().ok());
    if let Some(v) = env("PMB_GRID_POINTS") {
        options.grid_points = v;
    }
    if let Some(v) = env("PMB_SUB1") {
        options.refine_subsample[0] = v;
    }
    if let Some(v) = env("PMB_HESS_EVERY") {
        options.refine.hessian_every = v;
    }
    let (scene, t_scene, c_scene) = timed(|| mi_scene(&input, &start, &options));
    let scene = scene?;
    let (coarse, t_sub, c_sub) = timed(|| grid_scene(&scene, &options));
    let (grid, t_grid, c_grid) = timed(|| grid_stage(&coarse, &input.image, &start, &options));
    let after_grid = grid_pose(&start, &grid.best);
    let ((refined, _), t_ref, c_ref) =
        timed(|| refine_stage(&scene, &input.image, &after_grid, &options));
    write_problem(&dir, &coarse, &input.image, &start, &truth, &options)?;
    let err = |x: &Isometry3<f64>| {
        (
            (x.translation.vector - truth.translation.vector).norm() * 100.0,
            yaw_error(x, &truth).to_degrees(),
            (truth.rotation.inverse() * x.rotation).angle().to_degrees(),
        )
    };
    let (pg, yg, _) = err(&after_grid);
    let (pr, yr, rr) = err(&refined.x);
    let b = &grid.best;
    println!(
        "seed {seed}, {} map points, {} in view, grid on {}; start {OFFSET:?} (m, m, m, deg) \
         off; rayon {} threads",
        input.map.points.len(),
        scene.points.len(),
        coarse.points.len(),
        rayon::current_num_threads()
    );
    println!("| stage | wall (s) | CPU (s) | evaluations | MI at optimum | pose found |");
    println!("|---|---:|---:|---:|---:|---|");
    println!(
        "| setup (points in view, rank, equalise + blur) | {:.3} | {:.2} | - | - | - |",
        t_scene + t_sub,
        c_scene + c_sub
    );
    println!(
        "| msreg 4-DoF grid ({} levels x {} candidates, hard MI) | {t_grid:.3} | {c_grid:.2} | {} \
         | {:.5} | d = ({:.3}, {:.3}, {:.3}) m, {:.3} deg; error {pg:.1} cm, yaw {yg:.3} deg |",
        options.grid_levels,
        (2 * options.grid_steps + 1).pow(4),
        grid.evaluations,
        grid.mi,
        b[0],
        b[1],
        b[2],
        b[3].to_degrees()
    );
    println!(
        "| msreg 6-DoF refinement (blur {:?} px, every {:?}-th of {} points) | {t_ref:.3} | {c_ref:.2} | {} \
         iterations | {:.5} (smoothed) | error {pr:.2} cm, yaw {yr:.4} deg, rotation {rr:.4} deg |",
        options.refine_blur_px,
        options.refine_subsample,
        scene.points.len(),
        refined.iterations,
        refined.smoothed.mi
    );
    println!(
        "| msreg grid + refinement | {:.3} | {:.2} | | | |",
        t_grid + t_ref,
        c_grid + c_ref
    );
    Ok(())
}

/// `points.bin` (f64 x, y, z, rank-normalised value per grid point), `image.f32` (the
/// equalised, blurred image the grid samples, row-major f32), `problem.txt`.
fn write_problem(
    dir: &str,
    coarse: &MiScene,
    image: &msreg_host::vision::GrayImage,
    start: &Isometry3<f64>,
    truth: &Isometry3<f64>,
    options: &RegisterOptions,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut bytes = Vec::with_capacity(coarse.points.len() * 32);
    for (p, &v) in coarse.points.iter().zip(&coarse.values) {
        for x in [p.x, p.y, p.z, f64::from(v)] {
            bytes.extend_from_slice(&x.to_le_bytes());
        }
    }
    std::fs::write(format!("{dir}/points.bin"), bytes)?;
    let blurred = equalize(image).gaussian_blur(options.grid_blur_px);
    let pixels: Vec<u8> = blurred
        .data()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(format!("{dir}/image.f32"), pixels)?;
    let cam = &coarse.camera;
    let (Projection::Pinhole, Distortion::Equidistant(d)) = (cam.projection(), cam.distortion())
    else {
        return Err("the anchor implements the equidistant fisheye only".into());
    };
    let k = cam.intrinsics();
    let row = |t: &Isometry3<f64>| {
        let m = t.to_homogeneous().transpose();
        m.as_slice()
            .iter()
            .map(|v| format!("{v:.17e}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let h = options.grid_half;
    let mut f = std::fs::File::create(format!("{dir}/problem.txt"))?;
    writeln!(f, "# width height; equidistant fu fv cu cv k1 k2 k3 k4")?;
    writeln!(f, "{} {}", blurred.width(), blurred.height())?;
    writeln!(
        f,
        "{:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e}",
        k.fu, k.fv, k.cu, k.cv, d.k1, d.k2, d.k3, d.k4
    )?;
    writeln!(f, "# start T_world_cam row-major 4x4, then truth")?;
    writeln!(f, "{}", row(start))?;
    writeln!(f, "{}", row(truth))?;
    writeln!(
        f,
        "# half ranges x y z (m) yaw (rad), steps, levels, bins, min depth"
    )?;
    writeln!(
        f,
        "{:.17e} {:.17e} {:.17e} {:.17e} {} {} {} {}",
        h[0],
        h[1],
        h[2],
        h[3],
        options.grid_steps,
        options.grid_levels,
        coarse.bins,
        coarse.min_depth
    )?;
    Ok(())
}
