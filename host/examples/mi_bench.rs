//! Benchmark of the MI engine (issue 15): the 4-DoF (x, y, z, yaw) coarse-to-fine grid plus
//! the 6-DoF refinement over 100k map points, a downward equidistant fisheye 8 m above a
//! textured ground (`msreg_host::mi::synthetic`). Prints a markdown table and writes the
//! problem to `<dir>` (default /tmp/mi_bench). The NumPy anchor `tools/mi_grid_numpy.py`
//! now reads the prior-map problem of `--example prior_map_bench` instead.
//!
//! `cargo run --release -p msreg-host --example mi_bench [-- <dir>]`

use std::io::Write;
use std::time::Instant;

use msreg_host::mi::scene::{MiScene, PoseParam};
use msreg_host::mi::search::{grid_search, refine, GridAxis, GridScore, RefineOptions};
use msreg_host::mi::synthetic::synthetic_ground;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

const POINTS: usize = 100_000;
const OFFSET: [f64; 4] = [0.8, -0.6, 0.3, 4.0];
const HALF_RANGE: [f64; 4] = [1.2, 1.2, 0.6, 6.0];
const STEPS: usize = 1;
const LEVELS: usize = 7;
const SUBSAMPLE: usize = 8;

fn main() -> std::io::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "/tmp/mi_bench".into());
    let g = synthetic_ground(3, POINTS);
    let truth = g.t_world_cam;
    let start = Isometry3::from_parts(
        Translation3::from(
            truth.translation.vector + Vector3::new(OFFSET[0], OFFSET[1], OFFSET[2]),
        ),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), OFFSET[3].to_radians())
            * truth.rotation,
    );
    write_problem(&dir, &g, &start)?;
    let clock = Instant::now();
    let coarse = MiScene::new(g.points.clone(), &g.intensities, &g.image, g.camera, 4.0);
    let fine = coarse.with_image(&g.image, 1.0);
    let t_setup = clock.elapsed().as_secs_f64();
    let axes: Vec<GridAxis> = HALF_RANGE
        .iter()
        .enumerate()
        .map(|(i, &h)| GridAxis {
            half_range: if i == 3 { h.to_radians() } else { h },
            steps: STEPS,
        })
        .collect();
    let pose = |v: &[f64]| {
        Isometry3::from_parts(
            Translation3::from(start.translation.vector + Vector3::new(v[0], v[1], v[2])),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), v[3]) * start.rotation,
        )
        .inverse()
    };
    let clock = Instant::now();
    let grid = grid_search(
        &coarse.subsampled(SUBSAMPLE),
        &axes,
        LEVELS,
        GridScore::Smoothed,
        pose,
    );
    let t_grid = clock.elapsed().as_secs_f64();
    let param = PoseParam::SourceFromCam;
    let clock = Instant::now();
    let mid = refine(
        &coarse,
        param,
        &pose(&grid.best).inverse(),
        &RefineOptions::default(),
    );
    let r = refine(&fine, param, &mid.x, &RefineOptions::default());
    let t_refine = clock.elapsed().as_secs_f64();
    let after_grid = pose(&grid.best).inverse();
    let err = |x: &Isometry3<f64>| {
        (
            (x.translation.vector - truth.translation.vector).norm() * 100.0,
            (truth.rotation.inverse() * x.rotation).angle().to_degrees(),
        )
    };
    let (pg, rg) = err(&after_grid);
    let (pr, rr) = err(&r.x);
    println!("| stage | time (s) | evaluations | position error (cm) | rotation error (deg) |");
    println!("|---|---|---|---|---|");
    println!("| setup (equalise + blur images) | {t_setup:.3} | - | - | - |");
    println!(
        "| 4-DoF grid ({} levels x {} candidates, {} points) | {t_grid:.3} | {} | {pg:.1} | {rg:.3} |",
        LEVELS,
        (2 * STEPS + 1).pow(4),
        POINTS / SUBSAMPLE,
        grid.evaluations
    );
    println!(
        "| 6-DoF refinement (blur 4 px on {} points, then 1 px on {POINTS}) | {t_refine:.3} | {} iterations | {pr:.2} | {rr:.4} |",
        POINTS / 4,
        mid.iterations + r.iterations
    );
    println!(
        "| total grid + refinement | {:.3} | | | |",
        t_grid + t_refine
    );
    println!(
        "threads: {}; MI {:.4} NMI {:.4}",
        rayon::current_num_threads(),
        r.smoothed.mi,
        r.smoothed.nmi
    );
    Ok(())
}

/// points.bin (f64 x, y, z, intensity per point), image.pgm, problem.txt (camera, start).
fn write_problem(
    dir: &str,
    g: &msreg_host::mi::synthetic::SyntheticGround,
    start: &Isometry3<f64>,
) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut bytes = Vec::with_capacity(g.points.len() * 32);
    for (p, &i) in g.points.iter().zip(&g.intensities) {
        for v in [p.x, p.y, p.z, f64::from(i)] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(format!("{dir}/points.bin"), bytes)?;
    let img = g.image.to_luma8();
    let mut pgm = format!("P5\n{} {}\n255\n", img.width(), img.height()).into_bytes();
    pgm.extend_from_slice(img.as_raw());
    std::fs::write(format!("{dir}/image.pgm"), pgm)?;
    let m = start.to_homogeneous();
    let truth = g.t_world_cam.to_homogeneous();
    let mut f = std::fs::File::create(format!("{dir}/problem.txt"))?;
    writeln!(f, "# equidistant fu fv cu cv k1 k2 k3 k4")?;
    writeln!(f, "190 190 319.5 239.5 0.02 -0.01 0 0")?;
    writeln!(f, "# start T_world_cam row-major 4x4, then truth")?;
    writeln!(
        f,
        "{}",
        m.transpose()
            .as_slice()
            .iter()
            .map(|v| format!("{v:.17e}"))
            .collect::<Vec<_>>()
            .join(" ")
    )?;
    writeln!(
        f,
        "{}",
        truth
            .transpose()
            .as_slice()
            .iter()
            .map(|v| format!("{v:.17e}"))
            .collect::<Vec<_>>()
            .join(" ")
    )?;
    writeln!(f, "# half ranges x y z yaw_deg, steps, levels, subsample")?;
    writeln!(
        f,
        "{} {} {} {} {STEPS} {LEVELS} {SUBSAMPLE}",
        HALF_RANGE[0], HALF_RANGE[1], HALF_RANGE[2], HALF_RANGE[3]
    )?;
    Ok(())
}
