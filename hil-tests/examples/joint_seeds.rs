//! The firmware's joint self-test (`firmware/src/joint/`, `JointEkf<f32>`) on the host, over
//! many noise seeds: how consistent the device's joint filter is, where the self-test itself
//! can only look at one draw.
//!
//! The firmware's own modules (sequence generator, filter setup, due-ordered feeding, result
//! assessment) are compiled here for the host from their source files, so the run is the
//! device's, digit for digit (seed 0 prints the numbers `tools/firmware.sh run` prints).
//! Seed 0 is the self-test's sequence; seed k > 0 changes the IMU/LiDAR and the
//! camera/LiDAR-point noise seeds only (trajectory, priors and truth stay).
//!
//! ```text
//! cargo run --release -p msreg-hil-tests --example joint_seeds -- [--seeds N] [--seconds S]
//!     [--exact-priors] [--no-planes] [--no-poses] [--gauge] [--trace SEED]
//! ```
//!
//! Prints, per seed, every error over its reported 1-sigma (LiDAR and camera: rotation x y
//! z, translation x y z, `t_d`; board: rotation, position) and whether every update was
//! accepted; then per axis the RMS of those ratios over the seeds (1 for a consistent filter)
//! and the number of seeds with any axis beyond 3. `--exact-priors` starts both extrinsics
//! at the truth (the board from the exact camera), `--no-planes` / `--no-poses` leave the
//! board planes / LiDAR relative poses out, `--gauge` fixes the gauge at the board
//! (`Ekf::fix_gauge`), `--trace` prints every measurement update of one seed.
#![allow(missing_docs, clippy::float_cmp, clippy::too_many_lines)]

#[path = "../../firmware/src/joint/mod.rs"]
pub mod joint;
#[path = "../../firmware/src/noise.rs"]
pub mod noise;
#[path = "../../firmware/src/propagation.rs"]
pub mod propagation;
#[path = "../../firmware/src/scenario.rs"]
pub mod scenario;
#[path = "../../firmware/src/selftest.rs"]
pub mod selftest;
#[path = "../../firmware/src/trajectory.rs"]
pub mod trajectory;

#[path = "../joint_seeds/harness.rs"]
mod harness;

use harness::{row, run, summarize, Options};

fn parse() -> Result<Options, String> {
    let mut o = Options {
        seeds: 40,
        ..Options::default()
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| {
            args.next()
                .and_then(|v| v.parse::<u64>().ok())
                .ok_or(format!("{name} needs a number"))
        };
        match a.as_str() {
            "--seeds" => o.seeds = u32::try_from(value("--seeds")?).map_err(|e| e.to_string())?,
            "--seconds" => o.seconds = Some(value("--seconds")?),
            "--trace" => {
                o.trace = Some(u32::try_from(value("--trace")?).map_err(|e| e.to_string())?);
            }
            "--exact-priors" => o.exact_priors = true,
            "--no-planes" => o.no_planes = true,
            "--no-poses" => o.no_poses = true,
            "--gauge" => o.gauge = true,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(o)
}

fn main() {
    let o = match parse() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("joint_seeds: {e}");
            std::process::exit(2);
        }
    };
    if let Some(k) = o.trace {
        if let Err(e) = run(k, &o) {
            eprintln!("joint_seeds: seed {k}: {e}");
            std::process::exit(1);
        }
        return;
    }
    let summary = match summarize(&o, |k, r| {
        println!(
            "seed {k:3} all accepted {} | LiDAR [{}] | camera [{}] | board [{}] | NEES [{}]",
            r.all_accepted,
            row(&r.lidar),
            row(&r.camera),
            row(&r.board),
            row(&r.nees)
        );
    }) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("joint_seeds: {e}");
            std::process::exit(1);
        }
    };
    for (g, (name, axes)) in [("LiDAR", 7), ("camera", 7), ("board", 6)]
        .iter()
        .enumerate()
    {
        let rms: Vec<f32> = summary.rms[g][..*axes].iter().map(|x| *x as f32).collect();
        println!(
            "{name:6} RMS error/sigma per axis [{}]; seeds with an axis beyond 3: {}/{}; \
             mean 6-dof NEES {:.2} (6 if consistent), above chi2(6) 99 %: {}/{}",
            row(&rms),
            summary.beyond[g],
            o.seeds,
            summary.nees_mean[g],
            summary.nees_over[g],
            o.seeds
        );
    }
    println!(
        "seeds with a gate rejection or an error: {}/{}",
        summary.rejected, o.seeds
    );
}
