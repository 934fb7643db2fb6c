//! The device's joint filter (`JointEkf<f32>`, the firmware's own joint self-test modules
//! compiled for the host) over 40 noise seeds: how consistent it is, which the device's
//! one-draw self-test cannot say.
//!
//! Measured on 2026-11-27 with the image update linearised once per image (the batch update;
//! docs/firmware.md, "Joint layout: consistency over 40 seeds"), mean 6-dof NEES (6 for a
//! consistent filter) of the LiDAR extrinsic / camera extrinsic / board pose, corner by
//! corner against one linearisation point, then compressed into one update per image:
//! - the self-test's run (3 s, camera prior 3 deg and 6 cm off): 12.85 / 17.84 / 28.63, then
//!   12.78 / 15.58 / 29.25;
//! - priors at the truth, 10 s: 6.77 / 7.22 / 10.38, then 6.77 / 7.23 / 10.37.
//!
//! The bounds are 1.5x the first of each pair.
//!
//! The relinearising corner-by-corner update it replaced gave 85.4 / 275.5 / 142.8 on the
//! self-test's run: these bounds (1.5x the measured values) fail on it. The remaining
//! excess from the 3 deg start is an open finding (linearisation across images), so the
//! bounds guard what holds; they are not the consistency target (6).

#![allow(missing_docs, clippy::float_cmp)]

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

use harness::{summarize, Options};

fn mean_nees(o: &Options) -> [f64; 3] {
    summarize(o, |_, _| {}).expect("every seed runs").nees_mean
}

#[test]
fn the_joint_self_test_run_over_40_noise_seeds_stays_near_its_measured_consistency() {
    let o = Options {
        seeds: 40,
        ..Options::default()
    };
    let nees = mean_nees(&o);
    eprintln!("self-test run, 40 seeds: mean 6-dof NEES LiDAR / camera / board {nees:.2?}");
    for (name, (got, bound)) in ["LiDAR", "camera", "board"]
        .iter()
        .zip(nees.iter().zip([19.3, 26.8, 42.9]))
    {
        assert!(*got < bound, "{name}: mean NEES {got:.2} >= {bound}");
    }
}

#[test]
fn from_exact_priors_the_extrinsics_are_near_consistent_over_40_noise_seeds() {
    let o = Options {
        seeds: 40,
        seconds: Some(10),
        exact_priors: true,
        ..Options::default()
    };
    let nees = mean_nees(&o);
    eprintln!("exact priors, 10 s, 40 seeds: mean 6-dof NEES LiDAR / camera / board {nees:.2?}");
    for (name, (got, bound)) in ["LiDAR", "camera", "board"]
        .iter()
        .zip(nees.iter().zip([10.2, 10.8, 15.6]))
    {
        assert!(*got < bound, "{name}: mean NEES {got:.2} >= {bound}");
    }
}
