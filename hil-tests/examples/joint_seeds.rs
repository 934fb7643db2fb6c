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
#[path = "../../firmware/src/scenario.rs"]
pub mod scenario;
#[path = "../../firmware/src/selftest.rs"]
pub mod selftest;
#[path = "../../firmware/src/trajectory.rs"]
pub mod trajectory;

use std::mem::MaybeUninit;

use joint::scenario::{euroc_camera, JointConfig, JointEvent, JointScenario};
use joint::selftest::{self as jst, JointCounts, JointSetup};
use joint::{JointFilter, BOARD_FRAME, CAMERA, LIDAR};
use msreg_estimator::{FilterConfig, InitialState, Pose};
use scenario::{Event, ImuReading, Scenario};

/// What to run.
#[derive(Clone, Copy, Default)]
struct Options {
    seeds: u32,
    seconds: Option<u64>,
    exact_priors: bool,
    no_planes: bool,
    no_poses: bool,
    gauge: bool,
    trace: Option<u32>,
}

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

/// The self-test's sequence (seed 0) or one with other noise seeds.
fn config(k: u32, o: &Options) -> JointConfig {
    let mut c = JointConfig::default_run();
    if k > 0 {
        c.base.seed = 0x5EED_0001u32.wrapping_add(k.wrapping_mul(2_654_435_761));
        c.seed = 0x5EED_0C01u32.wrapping_add(k.wrapping_mul(40_503));
    }
    if let Some(s) = o.seconds {
        c.base.duration_ns = s * 1_000_000_000;
    }
    c
}

/// `joint::selftest::place_filter`, with the priors at the truth when asked.
fn place<'a>(
    slot: &'a mut MaybeUninit<JointFilter>,
    setup: &JointSetup,
    first: &ImuReading,
    o: &Options,
) -> Result<&'a mut JointFilter, String> {
    let c = &setup.config;
    if !o.exact_priors {
        return jst::place_filter(slot, setup, first).map_err(|e| e.to_string());
    }
    let init = InitialState::at_rest(first.accel)
        .ok_or("first IMU sample not at rest")?
        .with_extrinsic(LIDAR, jst::truth(c, LIDAR), 0.1, 0.1)
        .with_time_offset(LIDAR, 0.0, jst::TIME_OFFSET_SIGMA)
        .with_extrinsic(CAMERA, jst::truth(c, CAMERA), 0.1, 0.1)
        .with_time_offset(CAMERA, 0.0, jst::TIME_OFFSET_SIGMA);
    let config = FilterConfig::new(selftest::imu_noise(&c.base.spec));
    let filter = slot.write(JointFilter::new(&config, &init).map_err(|e| e.to_string())?);
    let scenario = JointScenario::new(*c).ok_or("invalid joint config")?;
    let t_c_t = scenario.camera_to_board(c.camera_time_offset);
    let t_c_t = Pose::new(t_c_t.rotation, t_c_t.translation.vector);
    let board = filter
        .imu()
        .pose()
        .compose(&jst::truth(c, CAMERA))
        .compose(&t_c_t);
    filter
        .init_frame(BOARD_FRAME, board, jst::BOARD_SIGMA.0, jst::BOARD_SIGMA.1)
        .map_err(|e| e.to_string())?;
    Ok(filter)
}

/// Errors over sigma at the end of one run: LiDAR (7), camera (7), board (6).
struct Run {
    lidar: [f32; 7],
    camera: [f32; 7],
    board: [f32; 6],
    all_accepted: bool,
}

fn ratios(filter: &JointFilter, c: &JointConfig, s: usize) -> [f32; 7] {
    let r = jst::sensor_result(filter, c, s);
    let mut out = [r.time_offset_normalized; 7];
    out[..6].copy_from_slice(r.normalized.as_slice());
    out
}

fn board(filter: &JointFilter, c: &JointConfig) -> [f32; 6] {
    let mut out = [f32::NAN; 6];
    if let Some(b) = jst::board_normalized(filter, c) {
        out.copy_from_slice(b.as_slice());
    }
    out
}

fn row(v: &[f32]) -> String {
    v.iter()
        .map(|x| format!("{x:6.2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn skipped(event: &JointEvent, o: &Options) -> bool {
    (o.no_planes && matches!(event, JointEvent::Plane(_)))
        || (o.no_poses && matches!(event, JointEvent::LidarIncrement(_)))
}

fn run(k: u32, o: &Options) -> Result<Run, String> {
    let c = config(k, o);
    let setup = JointSetup {
        config: c,
        camera: euroc_camera().ok_or("camera model invalid")?,
    };
    let Some(Event::Imu(first)) = Scenario::new(c.base).next() else {
        return Err("the sequence does not start with an IMU sample".into());
    };
    let mut slot = Box::new(MaybeUninit::<JointFilter>::uninit());
    let filter = place(&mut slot, &setup, &first, o)?;
    if o.gauge {
        filter.fix_gauge(BOARD_FRAME).map_err(|e| e.to_string())?;
    }
    let mut events = JointScenario::new(c).ok_or("invalid joint config")?;
    let mut counts = JointCounts::default();
    let trace = o.trace == Some(k);
    let mut n = 0;
    jst::drive(filter, events.by_ref(), |f, event| {
        if skipped(event, o) {
            return;
        }
        let outcome = jst::feed(f, &setup, event);
        counts.record(event, &outcome);
        if let (true, Ok(Some(report))) = (trace, &outcome) {
            n += 1;
            println!(
                "{n:3} {:?} NIS/dof {:5.2} | LiDAR [{}] | camera [{}] | board [{}]",
                report.kind,
                report.nis / report.dof as f32,
                row(&ratios(f, &c, LIDAR)),
                row(&ratios(f, &c, CAMERA)),
                row(&board(f, &c))
            );
        }
    });
    let t = [counts.relative_poses, counts.images, counts.planes];
    Ok(Run {
        lidar: ratios(filter, &c, LIDAR),
        camera: ratios(filter, &c, CAMERA),
        board: board(filter, &c),
        all_accepted: counts.errors == 0 && t.iter().all(|t| t.accepted == t.calls),
    })
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
    let mut squares = [[0.0f64; 7]; 3];
    let mut beyond = [0u32; 3];
    let mut rejected = 0;
    for k in 0..o.seeds {
        let r = match run(k, &o) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("joint_seeds: seed {k}: {e}");
                std::process::exit(1);
            }
        };
        println!(
            "seed {k:3} all accepted {} | LiDAR [{}] | camera [{}] | board [{}]",
            r.all_accepted,
            row(&r.lidar),
            row(&r.camera),
            row(&r.board)
        );
        rejected += u32::from(!r.all_accepted);
        for (g, v) in [&r.lidar[..], &r.camera[..], &r.board[..]]
            .iter()
            .enumerate()
        {
            for (s, x) in squares[g].iter_mut().zip(v.iter()) {
                *s += f64::from(*x).powi(2);
            }
            beyond[g] += u32::from(v.iter().any(|x| x.abs() > 3.0));
        }
    }
    let n = f64::from(o.seeds.max(1));
    for (g, (name, axes)) in [("LiDAR", 7), ("camera", 7), ("board", 6)]
        .iter()
        .enumerate()
    {
        let rms: Vec<f32> = squares[g][..*axes]
            .iter()
            .map(|s| (s / n).sqrt() as f32)
            .collect();
        println!(
            "{name:6} RMS error/sigma per axis [{}]; seeds with an axis beyond 3: {}/{}",
            row(&rms),
            beyond[g],
            o.seeds
        );
    }
    println!(
        "seeds with a gate rejection or an error: {rejected}/{}",
        o.seeds
    );
}
