//! `msreg`: the command line over the host library.
//!
//! Exit codes (docs/formats.md): 0 success; 1 the calibration ran but did not converge or
//! failed its checks (the result is still written, with the reason); 2 bad input.

mod cli;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::anyhow;
use clap::{Args, Parser, Subcommand};
use cli::outcome::Outcome;
use msreg_host::calibrate::driver::report::{PoseImuOptions, SectionFrame};
use msreg_host::calibrate::pose_imu::{self, PoseImuInput};
use msreg_host::check::Needs;
use msreg_host::dataset::{CalibrationResult, Dataset, SectionName};
use msreg_host::eval;
use msreg_host::export::ExportFormat;
use msreg_host::sim::{self, SimConfig};

#[derive(Parser)]
#[command(
    name = "msreg",
    version = concat!(env!("CARGO_PKG_VERSION"), " (git ", env!("MSREG_GIT_REVISION"), ")"),
    about = "Extrinsic calibration of LiDARs, cameras and IMUs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write a simulated dataset with ground truth.
    Simulate {
        #[command(subcommand)]
        scenario: Scenario,
    },
    /// Calibrate from a dataset directory, or straight from a ROS 1 bag / MCAP file (read
    /// through a temporary dataset with the topic and config flags of `msreg convert`).
    Calibrate {
        /// Topics and noise files when the dataset argument is a bag.
        #[command(flatten)]
        bag: cli::convert::BagFlags,
        /// Also write the result for another tool, next to the result file, after a
        /// successful calibration: kalibr, openvins, vins-fusion, urdf or tf (as `msreg
        /// export`).
        #[arg(long, global = true, value_parser = cli::export::parse_format)]
        format: Option<ExportFormat>,
        #[command(subcommand)]
        task: Task,
    },
    /// Check a dataset directory (or a bag) before calibrating: missing files, stream
    /// overlap, rates and gaps, units, unknown keys, clock offsets, excitation and the
    /// target's scale. Exit code 2 when it finds an error.
    Check(cli::check::CheckArgs),
    /// Convert a ROS 1 bag or an MCAP file to a dataset directory.
    Convert(cli::convert::ConvertArgs),
    /// Write a result file for Kalibr, OpenVINS, VINS-Fusion, URDF or ROS tf.
    Export(cli::export::ExportArgs),
    /// Errors of a result file against a dataset's groundtruth/.
    Eval {
        /// Result YAML.
        result: PathBuf,
        /// Dataset directory with groundtruth/extrinsics.yaml.
        dataset: PathBuf,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Simulate, calibrate and evaluate every pipeline (pose-IMU, camera-IMU, LiDAR-IMU,
    /// LiDAR-camera) on short recordings; prints one table of errors against ground truth.
    Demo(cli::demo::DemoArgs),
    /// Talk to the firmware over a serial port: replay a dataset, monitor, show a recording.
    Link {
        #[command(subcommand)]
        command: cli::link::LinkCommand,
    },
    /// NDT scan matching of one pair: prints T_target_source, fitness, iterations, time.
    Match(cli::match_cmd::MatchArgs),
    /// Detect calibration targets in images.
    Detect {
        #[command(subcommand)]
        target: DetectTarget,
    },
    /// Replay the calibration health monitor over IMU + pose0 + pose1 (alarms, timeline).
    Monitor(cli::monitor::MonitorArgs),
    /// A printable calibration target (SVG at exact physical size) and its target.yaml.
    Target {
        #[command(subcommand)]
        kind: cli::target::TargetCommand,
    },
}

#[derive(Subcommand)]
enum DetectTarget {
    /// Inner corners of a Kalibr checkerboard, as CSV `image,corner_id,u,v`.
    Checkerboard(cli::detect::DetectCornersArgs),
    /// Tag corners of a Kalibr AprilGrid (Kalibr ids `4 tag + k`), as CSV
    /// `image,corner_id,u,v`.
    Aprilgrid(cli::detect::DetectCornersArgs),
    /// ArUco markers, as CSV `image,id,u0,v0,...,u3,v3` (corners in OpenCV order).
    Aruco(cli::aruco::DetectArucoArgs),
    /// Bright blobs (e.g. infrastructure cameras in the fisheye), as CSV `image,u,v,area,peak`.
    Blobs(cli::aruco::DetectBlobsArgs),
}

// The variants are the subcommand names (`pose-imu`, `lidar-imu`, `camera-imu`).
#[allow(clippy::enum_variant_names)]
#[derive(Subcommand)]
enum Scenario {
    /// IMU + generic pose sensor (odometry) with drifting increments.
    PoseImu(SimulatePoseImu),
    /// IMU + spinning LiDAR (Ouster OS1-like, motion-distorted scans) in a box-world room.
    LidarImu(cli::lidar_imu::SimulateLidarImu),
    /// IMU + camera waved in front of a checkerboard (rendered images, true corners).
    CameraImu(cli::sim_camera::SimulateCameraImu),
    /// Static LiDAR + camera suite and a plain board at many still poses.
    LidarCamera(cli::lidar_camera::SimulateLidarCamera),
    /// IMU + camera + spinning LiDAR on one hand-held rig, in front of a checkerboard on a
    /// board both sensors see (joint calibration, both time offsets).
    Joint(cli::sim_joint::SimulateJoint),
    /// Robot with an upward fisheye and a marker driving a loop under ~40 static
    /// infrastructure cameras (marker corners, blobs, COLMAP VO model).
    Infra(cli::infra::SimulateInfra),
    /// On-vehicle monitoring: a car-like drive with IMU, LiDAR odometry (pose0) and camera
    /// visual odometry (pose1), a camera knock partway through.
    Drive(cli::sim_drive::SimulateDrive),
    /// A static downward fisheye at an intersection in a prior map (LiDAR map with
    /// reflectivity, satellite ortho image, GPS prior, survey points).
    PriorMap(cli::sim_prior_map::SimulatePriorMap),
    /// N cameras on a rig waved in front of a checkerboard or AprilGrid (intrinsics: any
    /// Kalibr model, true intrinsics, T_cn_cnm1 and corners in groundtruth/).
    Cameras(cli::sim_cameras::SimulateCameras),
    /// A rig of N IMUs on one hand-held motion, each further IMU at its own mounting, rate,
    /// noise and clock offset (truth in groundtruth/extrinsics.yaml).
    ImuImu(cli::imu_imu::SimulateImuImu),
}

#[derive(Args)]
struct SimulatePoseImu {
    /// Output directory (created).
    out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Recording length, s.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// Time offset of the pose sensor, ms (stamp + offset = IMU time).
    #[arg(long, default_value_t = 0.0)]
    time_offset_ms: f64,
    /// Pose sensor rate, Hz.
    #[arg(long, default_value_t = 10.0)]
    pose_rate: f64,
    /// Motion: hand-held (every axis excited, still start), a car-like planar drive, or a
    /// car's calibration figure-eight.
    #[arg(long, value_enum, default_value_t = MotionArg::Handheld)]
    motion: MotionArg,
}

/// `--motion` of `msreg simulate pose-imu`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum MotionArg {
    /// Hand-held sinusoids on every axis after a still start.
    Handheld,
    /// A car on a plane (figure-eight with wiggles, +-2 deg suspension roll / pitch).
    Drive,
    /// A car's calibration manoeuvre: a clean parking-lot figure-eight with tight turns.
    FigureEight,
}

#[derive(Subcommand)]
enum Task {
    /// Motion-based IMU to pose-sensor calibration (EKF over IMU + odometry).
    PoseImu(CalibratePoseImu),
    /// LiDAR-IMU calibration: predict, deskew, NDT, relative-pose update (EKF).
    LidarImu(cli::lidar_imu::CalibrateLidarImu),
    /// LiDAR-camera calibration with a plain board (PBPC-Cal or PPC-Cal), judged by MLRE.
    LidarCamera(cli::lidar_camera::CalibrateLidarCamera),
    /// Camera-IMU calibration from checkerboard or AprilGrid images: corner reprojection
    /// (RepErrCal) or PnP relative poses (MoCal) in the EKF.
    CameraImu(cli::camera_imu::CalibrateCameraImu),
    /// Intrinsics of any number of cameras (Kalibr's pinhole-radtan, pinhole-equidistant,
    /// omni-radtan, ds, eucm) and the camera chain `T_cn_cnm1`, from checkerboard or
    /// AprilGrid images: one bundle adjustment.
    Cameras(cli::cameras::CalibrateCameras),
    /// Static infrastructure cameras registered from a robot's VO (COLMAP model), marker
    /// detections and blobs (chapter 6).
    Infra(cli::infra::CalibrateInfra),
    /// Joint LiDAR-IMU-camera calibration in one EKF (chapter 5): LiDAR relative poses,
    /// checkerboard corners and the board plane both sensors see.
    Joint(cli::joint::CalibrateJoint),
    /// A static (fisheye) camera registered in a prior map: LiDAR map with reflectivity,
    /// satellite ortho image, GPS prior (chapter 7; ORB + PnP, then mutual information).
    PriorMap(cli::prior_map::CalibratePriorMap),
    /// Every further IMU (imu1, imu2, ...) against imu0: rotation, lever arm and clock
    /// offset from both IMUs' gyros and accelerometers (batch least squares).
    ImuImu(cli::imu_imu::CalibrateImuImu),
}

#[derive(Args)]
struct CalibratePoseImu {
    /// Dataset directory (imu0/, pose0/), or a ROS 1 bag / MCAP file.
    dataset: PathBuf,
    /// Result YAML.
    #[arg(short, long, default_value = "result.yaml")]
    output: PathBuf,
    /// Report: an HTML page when the name ends in .html, else JSON (convergence history,
    /// sigmas, NIS, events).
    #[arg(long)]
    report: Option<PathBuf>,
    /// Keep the time offset fixed at zero.
    #[arg(long)]
    no_time_offset: bool,
    /// Run the filter in f32, as the firmware does.
    #[arg(long)]
    f32: bool,
    /// PNG plot of the extrinsic convergence (6 DoF and time offset, +-1 sigma bands).
    #[arg(long)]
    plot: Option<PathBuf>,
}

/// An error with the exit code it maps to.
enum Failure {
    BadInput(anyhow::Error),
    NotConverged(String),
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(e: E) -> Self {
        Failure::BadInput(e.into())
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::NotConverged(why)) => {
            eprintln!("msreg: calibration did not converge: {why}");
            ExitCode::from(1)
        }
        Err(Failure::BadInput(e)) => {
            eprintln!("msreg: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(command: Command) -> Result<(), Failure> {
    match command {
        Command::Calibrate { bag, format, task } => calibrate(&bag, format, task),
        Command::Check(args) => match cli::check::run(&args)? {
            true => Ok(()),
            false => Err(Failure::BadInput(anyhow!(
                "{}: the check found errors (listed above)",
                args.dataset.display()
            ))),
        },
        Command::Simulate {
            scenario: Scenario::PoseImu(args),
        } => simulate_pose_imu(&args),
        Command::Simulate {
            scenario: Scenario::LidarImu(args),
        } => Ok(cli::lidar_imu::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::CameraImu(args),
        } => Ok(cli::sim_camera::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::Joint(args),
        } => Ok(cli::sim_joint::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::LidarCamera(args),
        } => Ok(cli::lidar_camera::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::Infra(args),
        } => Ok(cli::infra::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::ImuImu(args),
        } => Ok(cli::imu_imu::simulate(&args)?),
        Command::Eval {
            result,
            dataset,
            json,
        } => evaluate(&result, &dataset, json),
        Command::Demo(args) => cli::demo::run_demo(&args),
        Command::Convert(args) => cli::convert::run(&args)
            .map(|_| ())
            .map_err(Failure::BadInput),
        Command::Link { command } => Ok(cli::link::run(command)?),
        Command::Detect {
            target: DetectTarget::Checkerboard(args) | DetectTarget::Aprilgrid(args),
        } => cli::detect::run(&args)
            .map(|_| ())
            .map_err(Failure::BadInput),
        Command::Detect {
            target: DetectTarget::Aruco(args),
        } => cli::aruco::run_aruco(&args)
            .map(|_| ())
            .map_err(Failure::BadInput),
        Command::Detect {
            target: DetectTarget::Blobs(args),
        } => cli::aruco::run_blobs(&args)
            .map(|_| ())
            .map_err(Failure::BadInput),
        Command::Simulate {
            scenario: Scenario::Drive(args),
        } => Ok(cli::sim_drive::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::PriorMap(args),
        } => Ok(cli::sim_prior_map::simulate(&args)?),
        Command::Simulate {
            scenario: Scenario::Cameras(args),
        } => Ok(cli::sim_cameras::simulate(&args)?),
        Command::Target { kind } => Ok(cli::target::run(&kind)?),
        Command::Monitor(args) => match cli::monitor::run(&args)? {
            cli::monitor::MonitorOutcome::Ran => Ok(()),
            cli::monitor::MonitorOutcome::Failed(why) => {
                eprintln!("msreg: monitor: {why}");
                std::process::exit(1)
            }
        },
        Command::Export(args) => Ok(cli::export::run(&args)?),
        Command::Match(args) => match cli::match_cmd::run(&args)? {
            cli::match_cmd::MatchOutcome { ok: true } => Ok(()),
            _ => Err(Failure::NotConverged(
                "NDT did not converge or the geometry is degenerate".into(),
            )),
        },
    }
}

/// `msreg calibrate <task>`: a bag given as the dataset is converted first (its temporary
/// dataset lives until the calibration has written its outputs); the dataset check runs
/// next (its errors stop with exit code 2); after a successful calibration the result is
/// also exported as `format`, next to the result file.
fn calibrate(
    bag: &cli::convert::BagFlags,
    format: Option<ExportFormat>,
    mut task: Task,
) -> Result<(), Failure> {
    let _converted = cli::convert::dataset_from_bag(task.dataset_mut(), bag)?;
    if let Some(needs) = task.needs() {
        cli::check::before_calibration(task.dataset_mut(), needs)?;
    }
    let output = task.output().to_path_buf();
    run_task(task)?;
    if let Some(format) = format {
        let dir = match output.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        cli::export::export_file(&output, format, &dir)?;
    }
    Ok(())
}

/// Runs one calibration.
fn run_task(task: Task) -> Result<(), Failure> {
    match task {
        Task::PoseImu(args) => calibrate_pose_imu(&args),
        Task::LidarImu(args) => exit_code_of(cli::lidar_imu::calibrate(&args)?),
        Task::LidarCamera(args) => exit_code_of(cli::lidar_camera::calibrate(&args)?),
        Task::CameraImu(args) => exit_code_of(cli::camera_imu::run(&args)?),
        Task::Cameras(args) => exit_code_of(cli::cameras::run(&args)?),
        Task::Joint(args) => exit_code_of(cli::joint::run(&args)?),
        Task::PriorMap(args) => exit_code_of(cli::prior_map::calibrate(&args)?),
        Task::ImuImu(args) => exit_code_of(cli::imu_imu::run(&args)?),
        Task::Infra(args) => match cli::infra::calibrate(&args)? {
            true => Ok(()),
            false => Err(Failure::NotConverged(
                "some infrastructure cameras could not be registered (listed above)".into(),
            )),
        },
    }
}

impl Task {
    /// What the dataset check asks of the dataset; `None` for the pipelines whose layout
    /// the check does not know (no IMU: cameras, lidar-camera, infra, prior-map).
    fn needs(&self) -> Option<Needs> {
        match self {
            Task::PoseImu(_) => Some(Needs::PoseImu),
            Task::CameraImu(_) => Some(Needs::CameraImu),
            Task::LidarImu(_) => Some(Needs::LidarImu),
            Task::Joint(_) => Some(Needs::Joint),
            _ => None,
        }
    }

    /// The result file every calibration writes.
    fn output(&self) -> &Path {
        match self {
            Task::PoseImu(args) => &args.output,
            Task::LidarImu(args) => &args.output,
            Task::LidarCamera(args) => &args.output,
            Task::CameraImu(args) => &args.output,
            Task::Cameras(args) => &args.output,
            Task::Joint(args) => &args.output,
            Task::Infra(args) => &args.output,
            Task::PriorMap(args) => &args.output,
            Task::ImuImu(args) => &args.output,
        }
    }

    /// The dataset argument every calibration takes.
    fn dataset_mut(&mut self) -> &mut PathBuf {
        match self {
            Task::PoseImu(args) => &mut args.dataset,
            Task::LidarImu(args) => &mut args.dataset,
            Task::LidarCamera(args) => &mut args.dataset,
            Task::CameraImu(args) => &mut args.dataset,
            Task::Cameras(args) => &mut args.dataset,
            Task::Joint(args) => &mut args.dataset,
            Task::Infra(args) => &mut args.dataset,
            Task::PriorMap(args) => &mut args.dataset,
            Task::ImuImu(args) => &mut args.dataset,
        }
    }
}

/// Exit code 0 or 1 of a calibration that ran.
fn exit_code_of(outcome: Outcome) -> Result<(), Failure> {
    match outcome {
        Outcome::Converged => Ok(()),
        Outcome::NotConverged(why) => Err(Failure::NotConverged(why)),
    }
}

fn simulate_pose_imu(args: &SimulatePoseImu) -> Result<(), Failure> {
    let mut config = SimConfig {
        seed: args.seed,
        duration_s: args.duration,
        ..SimConfig::default()
    };
    config.pose.time_offset_s = args.time_offset_ms * 1e-3;
    config.pose.rate_hz = args.pose_rate;
    config.trajectory.motion = match args.motion {
        MotionArg::Handheld => sim::MotionKind::Handheld,
        MotionArg::Drive => sim::MotionKind::Drive(sim::DriveConfig::default()),
        MotionArg::FigureEight => sim::MotionKind::Drive(sim::DriveConfig::figure_eight()),
    };
    let data = sim::simulate_pose_imu(&config).map_err(|e| anyhow!("simulate: {e}"))?;
    data.write(&args.out_dir)?;
    eprintln!(
        "msreg: wrote {} ({} IMU samples, {} poses)",
        args.out_dir.display(),
        data.imu.len(),
        data.pose.len()
    );
    Ok(())
}

fn calibrate_pose_imu(args: &CalibratePoseImu) -> Result<(), Failure> {
    let dataset = Dataset::open(&args.dataset)?;
    let input = PoseImuInput {
        imu: dataset.require_imu()?,
        imu_noise: dataset.require_imu_noise()?,
        poses: dataset.require_pose0()?,
        pose_noise: dataset.require_pose0_sensor()?,
    };
    let options = PoseImuOptions {
        estimate_time_offset: !args.no_time_offset,
        ..PoseImuOptions::default()
    };
    let bar = progress_bar();
    let mut progress = |f: f64| bar.set_position((f * 1000.0) as u64);
    let outcome = if args.f32 {
        pose_imu::calibrate::<f32>(&input, &options, &mut progress)
    } else {
        pose_imu::calibrate::<f64>(&input, &options, &mut progress)
    };
    bar.finish_and_clear();
    let calibration = outcome.map_err(|e: msreg_host::calibrate::InputError| {
        Failure::BadInput(anyhow!("{}: {e}", args.dataset.display()))
    })?;
    let mut result = CalibrationResult::new()
        .with_extrinsic(SectionName::POSE0, calibration.imu_sensor_estimate());
    result
        .section_mut(SectionName::POSE0)
        .hold_all(calibration.report.held_dofs(SectionFrame::ImuSensor));
    cli::outcome::write_outputs(
        &result,
        &args.output,
        args.report.as_deref(),
        &calibration.report,
    )?;
    eprintln!("msreg: wrote {}", args.output.display());
    warn_unobservable(&calibration.report.observability);
    if let Some(path) = &args.plot {
        let series =
            msreg_host::calibrate::convergence::extrinsic_series(&calibration.report.history, None);
        let title = format!("T_imu_pose convergence: {}", args.dataset.display());
        match msreg_host::plot::write_convergence_png(path, &title, &series, (1500, 1100)) {
            Ok(()) => eprintln!("msreg: wrote {}", path.display()),
            Err(e) => eprintln!("msreg: warning: {e}"),
        }
    }
    if !calibration.report.converged {
        return Err(Failure::NotConverged(calibration.report.reasons.join("; ")));
    }
    Ok(())
}

/// One warning per DoF the calibration could not observe or cannot vouch for, naming it
/// and why.
fn warn_unobservable(rows: &[msreg_host::calibrate::observability::DofObservability]) {
    for row in rows
        .iter()
        .filter(|r| r.status == "not observable" || r.status == "not trusted")
    {
        eprintln!(
            "msreg: warning: {} is {}: {} (sigma {:.3}, prior {:.3})",
            row.dof, row.status, row.reason, row.sigma, row.prior_sigma
        );
    }
}

fn progress_bar() -> indicatif::ProgressBar {
    cli::outcome::progress_bar(1000, "{spinner} filtering [{bar:40}] {percent}% {elapsed}")
}

fn evaluate(result: &Path, dataset: &Path, json: bool) -> Result<(), Failure> {
    let estimate = CalibrationResult::read(result)?;
    let truth = Dataset::open(dataset)?;
    let truth = truth.require_groundtruth_extrinsics()?;
    let errors = eval::evaluate(&estimate, truth);
    for hint in eval::convention_hints(&estimate, truth) {
        eprintln!("msreg: warning: {}: {hint}", result.display());
    }
    if errors.is_empty() {
        return Err(Failure::BadInput(anyhow!(
            "{}: no section in common with {}/groundtruth/extrinsics.yaml",
            result.display(),
            dataset.display()
        )));
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&errors)?);
    } else {
        print!("{}", eval::table(&errors));
    }
    Ok(())
}
