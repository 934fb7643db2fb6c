//! The joint self-test harness shared by the `joint_seeds` example and the
//! `joint_consistency` test: one seed of the firmware's joint self-test on the host
//! ([`run`]) and statistics over many ([`summarize`]). Its including crate declares the
//! firmware modules (`joint`, `noise`, `scenario`, `selftest`, `trajectory`) at its root.

use std::mem::MaybeUninit;

use crate::joint::scenario::{euroc_camera, JointConfig, JointEvent, JointScenario};
use crate::joint::selftest::{self as jst, JointCounts, JointSetup};
use crate::joint::{JointFilter, BOARD_FRAME, CAMERA, LIDAR};
use crate::scenario::{Event, ImuReading, Scenario};
use msreg_estimator::{FilterConfig, InitialState, Pose};

/// The 99 % quantile of chi-square with 6 degrees of freedom.
const NEES_6DOF_99: f32 = 16.81;

/// What to run.
#[derive(Clone, Copy, Default)]
pub struct Options {
    pub seeds: u32,
    pub seconds: Option<u64>,
    pub exact_priors: bool,
    pub no_planes: bool,
    pub no_poses: bool,
    pub gauge: bool,
    pub trace: Option<u32>,
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
    let config = FilterConfig::new(crate::selftest::imu_noise(&c.base.spec));
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
pub struct Run {
    pub lidar: [f32; 7],
    pub camera: [f32; 7],
    pub board: [f32; 6],
    /// 6-dof NEES of the LiDAR extrinsic, the camera extrinsic and the board pose.
    pub nees: [f32; 3],
    pub all_accepted: bool,
}

fn ratios(r: &jst::SensorResult) -> [f32; 7] {
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

pub fn row(v: &[f32]) -> String {
    v.iter()
        .map(|x| format!("{x:6.2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn skipped(event: &JointEvent, o: &Options) -> bool {
    (o.no_planes && matches!(event, JointEvent::Plane(_)))
        || (o.no_poses && matches!(event, JointEvent::LidarIncrement(_)))
}

pub fn run(k: u32, o: &Options) -> Result<Run, String> {
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
                row(&ratios(&jst::sensor_result(f, &c, LIDAR))),
                row(&ratios(&jst::sensor_result(f, &c, CAMERA))),
                row(&board(f, &c))
            );
        }
    });
    let t = [counts.relative_poses, counts.images, counts.planes];
    let (lidar, camera) = (
        jst::sensor_result(filter, &c, LIDAR),
        jst::sensor_result(filter, &c, CAMERA),
    );
    Ok(Run {
        lidar: ratios(&lidar),
        camera: ratios(&camera),
        board: board(filter, &c),
        nees: [
            lidar.nees,
            camera.nees,
            jst::board_nees(filter, &c).unwrap_or(f32::NAN),
        ],
        all_accepted: counts.errors == 0 && t.iter().all(|t| t.accepted == t.calls),
    })
}

/// Statistics over the seeds `0..o.seeds`; groups LiDAR, camera, board.
pub struct Summary {
    /// RMS of error / sigma per axis (LiDAR and camera: 7 axes with `t_d`; board: 6).
    pub rms: [[f64; 7]; 3],
    /// Seeds with any axis beyond 3 sigma.
    pub beyond: [u32; 3],
    /// Mean 6-dof NEES (6 for a consistent filter).
    pub nees_mean: [f64; 3],
    /// Seeds whose 6-dof NEES is above chi-square's 99 % quantile.
    pub nees_over: [u32; 3],
    /// Seeds with a gate rejection or an error.
    pub rejected: u32,
}

/// Runs every seed of `o`, hands each run to `each`, and sums up.
pub fn summarize(o: &Options, mut each: impl FnMut(u32, &Run)) -> Result<Summary, String> {
    let mut squares = [[0.0f64; 7]; 3];
    let mut out = Summary {
        rms: [[0.0; 7]; 3],
        beyond: [0; 3],
        nees_mean: [0.0; 3],
        nees_over: [0; 3],
        rejected: 0,
    };
    for k in 0..o.seeds {
        let r = run(k, o).map_err(|e| format!("seed {k}: {e}"))?;
        each(k, &r);
        for (g, x) in r.nees.iter().enumerate() {
            out.nees_mean[g] += f64::from(*x);
            // A NaN NEES (covariance not positive definite) counts as over.
            out.nees_over[g] += u32::from(x.is_nan() || *x > NEES_6DOF_99);
        }
        out.rejected += u32::from(!r.all_accepted);
        for (g, v) in [&r.lidar[..], &r.camera[..], &r.board[..]]
            .iter()
            .enumerate()
        {
            for (s, x) in squares[g].iter_mut().zip(v.iter()) {
                *s += f64::from(*x).powi(2);
            }
            out.beyond[g] += u32::from(v.iter().any(|x| x.abs() > 3.0));
        }
    }
    let n = f64::from(o.seeds.max(1));
    for ((mean, rms), squares) in out.nees_mean.iter_mut().zip(&mut out.rms).zip(&squares) {
        *mean /= n;
        for (r, s) in rms.iter_mut().zip(squares) {
            *r = (s / n).sqrt();
        }
    }
    Ok(out)
}
