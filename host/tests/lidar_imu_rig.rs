//! Two LiDARs on one IMU (issue 32, "the rig as data"): `lidar0` and `lidar1` ride the same
//! simulated hand-held motion with their own random mountings, time offsets (lidar1's 4 ms
//! below lidar0's) and range noise (`sim::lidar_rig`). Each is calibrated against `imu0` by
//! the LiDAR-IMU pipeline, as `msreg calibrate lidar-imu` does for every `lidarN/` folder.
//!
//! The CI test runs one seed on a 16 x 512 LiDAR for 20 s (~3 s per LiDAR); the acceptance
//! run (`#[ignore]`, ~60-85 s, so not in the CI list) five seeds of the 25 s 32 x 512 scenario
//! of `lidar_imu_accuracy.rs`, with its bounds, its 3-sigma check per axis and the NEES over
//! both LiDARs and all seeds.

#[path = "support/common.rs"]
mod common;
#[path = "support/lidar.rs"]
mod lidar_support;

use common::chi_square_band;
use lidar_support::{config, error};
use msreg_host::calibrate::lidar_imu::{self, LidarImuInput, LidarImuOptions};
use msreg_host::sim::{simulate_lidar_rig, LidarImuSim, LidarImuSimConfig};

/// One LiDAR's calibration against its truth.
struct Outcome {
    rot_deg: f64,
    trans_mm: f64,
    td_err_ms: f64,
    /// Every axis of the extrinsic and the time offset inside 3 sigma.
    inside: bool,
    nees: f64,
    converged: bool,
}

fn calibrate(lidar: &LidarImuSim, options: &LidarImuOptions) -> Outcome {
    let input = LidarImuInput {
        imu: &lidar.imu,
        imu_noise: &lidar.imu_noise,
        scans: lidar,
    };
    let c = lidar_imu::calibrate::<f64>(&input, options, &mut |_| {}).expect("calibration runs");
    let e = error(&c.t_imu_sensor, &lidar.t_imu_lidar);
    let sd = |i: usize| c.covariance[(i, i)].sqrt();
    let td_err = c.time_offset_s - lidar.config.lidar.time_offset_s;
    Outcome {
        rot_deg: c
            .t_imu_sensor
            .rotation
            .angle_to(&lidar.t_imu_lidar.rotation)
            .to_degrees(),
        trans_mm: (c.t_imu_sensor.translation.vector - lidar.t_imu_lidar.translation.vector).norm()
            * 1e3,
        td_err_ms: td_err * 1e3,
        inside: (0..6).all(|i| e[i].abs() <= 3.0 * sd(i))
            && td_err.abs() <= 3.0 * c.time_offset_sigma_s,
        nees: c
            .covariance
            .try_inverse()
            .map_or(f64::NAN, |info| e.dot(&(info * e))),
        converged: c.report.filter.converged,
    }
}

/// Calibrates every LiDAR of a `count`-LiDAR rig on `config`; prints and returns the outcomes.
fn run_rig(config: &LidarImuSimConfig, count: usize, options: &LidarImuOptions) -> Vec<Outcome> {
    let rig = simulate_lidar_rig(config, count).expect("valid simulation");
    rig.lidars
        .iter()
        .enumerate()
        .map(|(n, lidar)| {
            let o = calibrate(lidar, options);
            println!(
                "seed {} lidar{n}: {:.4} deg, {:.2} mm, td err {:+.3} ms, inside 3 sigma {}, \
                 NEES {:.2}, converged {}",
                config.seed, o.rot_deg, o.trans_mm, o.td_err_ms, o.inside, o.nees, o.converged
            );
            o
        })
        .collect()
}

fn assert_bounds(outcomes: &[Outcome], rot_deg: f64, trans_mm: f64, td_ms: f64) {
    for (k, o) in outcomes.iter().enumerate() {
        assert!(o.converged, "run {k}: not converged");
        assert!(o.inside, "run {k}: error outside 3 sigma");
        assert!(
            o.rot_deg < rot_deg && o.trans_mm < trans_mm && o.td_err_ms.abs() < td_ms,
            "run {k}: {:.4} deg, {:.2} mm, {:+.3} ms",
            o.rot_deg,
            o.trans_mm,
            o.td_err_ms
        );
    }
}

/// The faster anneal of the short CI recordings (`lidar_imu_accuracy.rs` says why).
fn options() -> LidarImuOptions {
    LidarImuOptions {
        anneal_updates: 45.0,
        ..LidarImuOptions::for_local_map(5)
    }
}

/// Both LiDARs of one 20 s recording (16 x 512) are calibrated, each inside its 3 sigma.
/// Bounds ~3x the worst of seeds 1-10 on this scenario (0.0120 deg, 1.40 mm, +0.035 ms over
/// the 20 calibrations; docs/lidar_imu.md, "Several LiDARs").
#[test]
fn two_lidars_on_one_imu_are_each_calibrated() {
    // `MSREG_SEED_LIST=1,2,3` runs other seeds, for experiments.
    let seeds: Vec<u64> = std::env::var("MSREG_SEED_LIST")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| vec![1]);
    let outcomes: Vec<Outcome> = seeds
        .iter()
        .flat_map(|&seed| run_rig(&config(seed, 20.0, 16, 512), 2, &options()))
        .collect();
    assert_eq!(outcomes.len(), 2 * seeds.len());
    assert_bounds(&outcomes, 0.04, 4.5, 0.1);
}

/// Five seeds of the 25 s 32 x 512 scenario, two LiDARs each: the bounds of
/// `lidar_imu_accuracy.rs` (0.04 deg, 3 mm, 0.2 ms) for every LiDAR and 3 sigma per axis.
/// Consistency, one-sided as the single-LiDAR pipeline is: its noise floors stand in for
/// NDT's time-correlated errors and make it conservative by design (docs/lidar_imu.md, "Not
/// done yet"; measured here: NEES sum 36.4 over the ten calibrations, 0.61 per dof, below the
/// 95 % band [40.5, 83.3] of chi-square(60)). So the summed NEES must stay under the band's
/// top (never overconfident) and above a third of the measured 0.61 per dof (sigmas at most
/// ~2.2x too wide).
#[test]
#[ignore = "acceptance run: ~60-85 s of CPU"]
fn two_lidars_over_five_seeds_are_accurate_and_consistent() {
    let outcomes: Vec<Outcome> = (1..=5)
        .flat_map(|seed| run_rig(&config(seed, 25.0, 32, 512), 2, &options()))
        .collect();
    assert_bounds(&outcomes, 0.04, 3.0, 0.2);
    let nees: f64 = outcomes.iter().map(|o| o.nees).sum();
    let dof = 6.0 * outcomes.len() as f64;
    let (lo, hi) = chi_square_band(dof);
    println!("NEES sum {nees:.2}, 95 % band [{lo:.2}, {hi:.2}]");
    assert!(
        nees <= hi,
        "NEES sum {nees:.2} above {hi:.2}: overconfident"
    );
    assert!(
        nees / dof > 0.2,
        "NEES per dof {:.3}: sigmas far too wide",
        nees / dof
    );
}
