//! `msreg match`: NDT of one scan pair, for checking scan matching on a user's own data.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{anyhow, bail, Context};
use clap::Args;
use msreg_host::ndt::{self, NdtParams};
use msreg_host::pointcloud::{read_pcd, voxel_downsample};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde_json::json;

/// Arguments of `msreg match`.
#[derive(Args)]
pub struct MatchArgs {
    /// Target scan (PCD).
    target: PathBuf,
    /// Source scan (PCD), aligned onto the target.
    source: PathBuf,
    /// Start guess of T_target_source: x,y,z [m],roll,pitch,yaw [rad] (ZYX).
    #[arg(long, allow_hyphen_values = true)]
    guess: Option<String>,
    /// Voxel size applied to both scans before matching, m (0 = none).
    #[arg(long, default_value_t = 0.2)]
    voxel: f64,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// What `run` found: whether the match converged without degeneracy.
pub struct MatchOutcome {
    /// Converged and not degenerate.
    pub ok: bool,
}

fn parse_guess(text: &str) -> anyhow::Result<Isometry3<f64>> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow!("--guess {text:?}: {e}"))?;
    let [x, y, z, roll, pitch, yaw] = v[..] else {
        bail!("--guess {text:?}: expected 6 comma-separated numbers x,y,z,roll,pitch,yaw");
    };
    if v.iter().any(|x| !x.is_finite()) {
        bail!("--guess {text:?}: values must be finite");
    }
    Ok(Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    ))
}

/// Runs the match and prints the result. Errors are bad input (exit 2).
pub fn run(args: &MatchArgs) -> anyhow::Result<MatchOutcome> {
    let guess = args
        .guess
        .as_deref()
        .map(parse_guess)
        .transpose()?
        .unwrap_or_else(Isometry3::identity);
    let target = read_pcd(&args.target)?;
    let source = read_pcd(&args.source)?;
    let (target, source) = if args.voxel > 0.0 {
        (
            voxel_downsample(&target, args.voxel),
            voxel_downsample(&source, args.voxel),
        )
    } else {
        (target, source)
    };
    let started = Instant::now();
    let result =
        ndt::align_scans(&target, &source, &guess, &NdtParams::default()).with_context(|| {
            format!(
                "matching {} onto {}",
                args.source.display(),
                args.target.display()
            )
        })?;
    let ms = started.elapsed().as_secs_f64() * 1e3;
    let m = result.t_target_source.to_homogeneous();
    let ok = result.converged && result.degenerate.is_none();
    if args.json {
        let rows: Vec<Vec<f64>> = (0..4)
            .map(|r| (0..4).map(|c| m[(r, c)]).collect())
            .collect();
        let out = json!({
            "T_target_source": rows,
            "fitness": result.fitness,
            "iterations": result.iterations,
            "converged": result.converged,
            "degenerate": result.degenerate.as_ref().map(|d| format!("{d:?}")),
            "time_ms": ms,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!("T_target_source:");
        for r in 0..4 {
            println!(
                "  [{:>12.6}, {:>12.6}, {:>12.6}, {:>12.6}]",
                m[(r, 0)],
                m[(r, 1)],
                m[(r, 2)],
                m[(r, 3)]
            );
        }
        println!(
            "fitness {:.4}, iterations {}, converged {}, time {:.1} ms",
            result.fitness, result.iterations, result.converged, ms
        );
        if let Some(d) = &result.degenerate {
            println!("degenerate geometry: {d:?}");
        }
    }
    Ok(MatchOutcome { ok })
}
