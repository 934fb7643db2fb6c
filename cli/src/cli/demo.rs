//! `msreg demo`: every calibration pipeline on a short simulated recording, run through the
//! same commands a user types (`simulate`, `calibrate`, then the errors of `eval`), and one
//! table of the errors against ground truth. The README's main job.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::{Args, Parser, ValueEnum};
use msreg_host::dataset::{CalibrationResult, Dataset};
use msreg_host::eval;

use crate::{run, Cli, Failure};

/// Arguments of `msreg demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Simulation seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Keep the datasets and outputs (result, report, plots) in this directory (default: a
    /// temporary one, removed at the end).
    #[arg(long)]
    keep: Option<PathBuf>,
    /// Run only these pipelines, comma separated (default: all).
    #[arg(long, value_enum, value_delimiter = ',')]
    only: Vec<Pipeline>,
}

/// A calibration pipeline of the demo.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Pipeline {
    /// IMU + drifting odometry, motion-based EKF.
    PoseImu,
    /// IMU + camera at a checkerboard, corner reprojection EKF.
    CameraImu,
    /// IMU + spinning LiDAR, NDT + deskewing EKF.
    LidarImu,
    /// LiDAR + camera at a plain board, PBPC-Cal.
    LidarCamera,
    /// IMU + LiDAR + camera at a checkerboard both see, one EKF with the board plane.
    Joint,
}

impl Pipeline {
    const ALL: [Pipeline; 5] = [
        Pipeline::PoseImu,
        Pipeline::CameraImu,
        Pipeline::LidarImu,
        Pipeline::LidarCamera,
        Pipeline::Joint,
    ];

    fn name(self) -> &'static str {
        match self {
            Pipeline::PoseImu => "pose-imu",
            Pipeline::CameraImu => "camera-imu",
            Pipeline::LidarImu => "lidar-imu",
            Pipeline::LidarCamera => "lidar-camera",
            Pipeline::Joint => "joint",
        }
    }

    /// What is simulated, for the printout.
    fn scenario(self) -> &'static str {
        match self {
            Pipeline::PoseImu => {
                "60 s hand-held, IMU 400 Hz (VN-300-class), odometry 10 Hz drifting 0.2 deg / 5 mm \
                 per increment, time offset 10 ms"
            }
            Pipeline::CameraImu => {
                "20 s, camera 20 Hz 752x480 at a 6x7 checkerboard (rendered, blur + noise), \
                 IMU 400 Hz, time offset 5 ms"
            }
            Pipeline::LidarImu => {
                "20 s in a room, 32 x 512 spinning LiDAR 10 Hz (motion-distorted scans), \
                 IMU 400 Hz, time offset 3 ms"
            }
            Pipeline::LidarCamera => {
                "30 still poses of a plain 1.0 x 0.8 m board, Ouster-like LiDAR, 1280x960 camera"
            }
            Pipeline::Joint => {
                "15 s hand-held at a 7x9 checkerboard on a board both sensors see, camera 20 Hz \
                 (rendered), 32 x 512 LiDAR 10 Hz, IMU 400 Hz, time offsets 5 / -8 ms"
            }
        }
    }

    /// Extra `msreg simulate <name> <dir>` options.
    fn simulate_options(self) -> &'static [&'static str] {
        match self {
            Pipeline::PoseImu => &["--time-offset-ms", "10"],
            Pipeline::CameraImu => &[
                "--duration",
                "20",
                "--noise",
                "--blur",
                "--time-offset-ms",
                "5",
            ],
            Pipeline::LidarImu => &[
                "--duration",
                "20",
                "--rings",
                "32",
                "--columns",
                "512",
                "--time-offset-ms",
                "3",
            ],
            Pipeline::LidarCamera => &["--lidar", "ouster"],
            Pipeline::Joint => &[
                "--duration",
                "15",
                "--rings",
                "32",
                "--columns",
                "512",
                "--camera-time-offset-ms",
                "5",
                "--lidar-time-offset-ms",
                "-8",
            ],
        }
    }

    /// The picture each calibration draws, as `msreg calibrate` options for a file name.
    fn picture_options(self) -> &'static [(&'static str, &'static str)] {
        match self {
            Pipeline::PoseImu | Pipeline::LidarImu => &[("--plot", "convergence.png")],
            Pipeline::CameraImu => &[
                ("--plot", "convergence.png"),
                ("--overlay", "reprojection.png"),
            ],
            Pipeline::LidarCamera => &[("--overlay", "edges.png")],
            Pipeline::Joint => &[],
        }
    }
}

/// Runs the command line `args` in this process, as `msreg args...` would.
fn in_process(args: &[String]) -> Result<(), Failure> {
    let cli = Cli::try_parse_from(std::iter::once("msreg".to_string()).chain(args.iter().cloned()))
        .map_err(|e| Failure::BadInput(anyhow::anyhow!("demo: {e}")))?;
    run(cli.command)
}

/// Runs the command line `args` as `msreg args...` would: in this process when the
/// directory is kept, else as a child process whose output lines naming the temporary
/// `hide` directory (removed at the end) are dropped. Where this executable cannot be
/// started as a child (exit status 126/127 or a spawn error: e.g. under qemu user-mode
/// emulation without binfmt, the aarch64 companion test), it runs in this process instead,
/// and the temporary paths are shown.
fn msreg(args: &[String], hide: Option<&Path>) -> Result<(), Failure> {
    let Some(hide) = hide else {
        return in_process(args);
    };
    let exe = std::env::current_exe().context("demo: cannot find the msreg executable")?;
    let output = match std::process::Command::new(exe).args(args).output() {
        Ok(output) if !matches!(output.status.code(), Some(126 | 127)) => output,
        _ => return in_process(args),
    };
    let hide = hide.to_string_lossy();
    let shown = |text: &[u8]| -> Vec<String> {
        String::from_utf8_lossy(text)
            .lines()
            .filter(|l| !l.contains(hide.as_ref()))
            .map(str::to_string)
            .collect()
    };
    shown(&output.stdout).iter().for_each(|l| println!("{l}"));
    let errors = shown(&output.stderr);
    errors.iter().for_each(|l| eprintln!("{l}"));
    let last = String::from_utf8_lossy(&output.stderr)
        .lines()
        .last()
        .unwrap_or("")
        .to_string();
    match output.status.code() {
        Some(0) => Ok(()),
        Some(1) => Err(Failure::NotConverged(
            last.trim_start_matches("msreg: calibration did not converge: ")
                .to_string(),
        )),
        _ => Err(Failure::BadInput(anyhow::anyhow!(
            "demo: `msreg {}` failed: {last}",
            args.first().map_or("", String::as_str)
        ))),
    }
}

/// One pipeline: simulate, calibrate, evaluate. Returns the error rows and a note.
fn demo_one(
    pipeline: Pipeline,
    seed: u64,
    dir: &Path,
    hide: Option<&Path>,
) -> Result<(String, String), Failure> {
    let name = pipeline.name();
    let data = dir.join("dataset");
    let path = |p: &Path| p.to_string_lossy().into_owned();
    let mut simulate = vec![
        "simulate".to_string(),
        name.into(),
        path(&data),
        "--seed".into(),
        seed.to_string(),
    ];
    simulate.extend(pipeline.simulate_options().iter().map(|s| s.to_string()));
    let started = Instant::now();
    msreg(&simulate, hide)?;
    let simulated_s = started.elapsed().as_secs_f64();
    let result = dir.join("result.yaml");
    let mut calibrate = vec![
        "calibrate".to_string(),
        name.into(),
        path(&data),
        "-o".into(),
        path(&result),
        "--report".into(),
        path(&dir.join("report.json")),
    ];
    for (option, file) in pipeline.picture_options() {
        calibrate.push(option.to_string());
        calibrate.push(path(&dir.join(file)));
    }
    let started = Instant::now();
    let converged = match msreg(&calibrate, hide) {
        Ok(()) => "converged".to_string(),
        Err(Failure::NotConverged(why)) => format!("DID NOT CONVERGE: {why}"),
        Err(e) => return Err(e),
    };
    let calibrated_s = started.elapsed().as_secs_f64();
    let estimate = CalibrationResult::read(&result)?;
    let truth = Dataset::open(&data)?;
    let errors = eval::evaluate(&estimate, truth.require_groundtruth_extrinsics()?);
    let note = format!(
        "{name:<13} {converged}; simulated in {simulated_s:.1} s, calibrated in {calibrated_s:.1} s"
    );
    Ok((eval::table_rows(&errors), note))
}

/// Runs the demo.
pub fn run_demo(args: &DemoArgs) -> Result<(), Failure> {
    let temp;
    let root = match &args.keep {
        Some(d) => d.clone(),
        None => {
            temp = tempfile::tempdir().context("demo: cannot create a temporary directory")?;
            temp.path().to_path_buf()
        }
    };
    let pipelines: Vec<Pipeline> = if args.only.is_empty() {
        Pipeline::ALL.to_vec()
    } else {
        Pipeline::ALL
            .into_iter()
            .filter(|p| args.only.contains(p))
            .collect()
    };
    println!(
        "msreg demo: simulate, calibrate and evaluate against ground truth (seed {}):",
        args.seed
    );
    for p in &pipelines {
        println!("  {:<13} {}", p.name(), p.scenario());
    }
    let started = Instant::now();
    let mut rows = String::new();
    let mut notes = Vec::new();
    for p in &pipelines {
        eprintln!("msreg demo: {} ...", p.name());
        let hide = args.keep.is_none().then_some(root.as_path());
        let (r, note) = demo_one(*p, args.seed, &root.join(p.name()), hide)?;
        rows.push_str(&format!("{}:\n{r}", p.name()));
        notes.push(note);
    }
    println!("\n{}{rows}", eval::TABLE_HEADER);
    for note in notes {
        println!("{note}");
    }
    println!("\ntotal {:.1} s", started.elapsed().as_secs_f64());
    if args.keep.is_some() {
        println!("datasets, results, reports and plots in {}", root.display());
    }
    Ok(())
}
