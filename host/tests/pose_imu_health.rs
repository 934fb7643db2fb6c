//! Online calibration health: a knocked sensor is flagged and re-estimated; an untouched
//! one is never flagged.

#[path = "support/common.rs"]
mod common;

use common::*;
use msreg_host::calibrate::driver::report::{HistoryPoint, PoseImuCalibration, PoseImuOptions};
use msreg_host::sim::{Knock, SimConfig};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

const KNOCK_AT_S: f64 = 30.0;

fn knocked_config(seed: u64) -> SimConfig {
    let mut c = SimConfig {
        seed,
        ..SimConfig::default()
    };
    // 1 deg about an axis that differs per seed.
    let axis = Vector3::new((seed as f64).sin(), (seed as f64 * 1.7).cos(), 0.5).normalize();
    c.pose.knock = Some(Knock {
        at_s: KNOCK_AT_S,
        delta: Isometry3::from_parts(
            Default::default(),
            UnitQuaternion::from_scaled_axis(axis * 1f64.to_radians()),
        ),
    });
    c
}

/// The extrinsic estimate at the last update at or before `t_s`.
fn estimate_at(c: &PoseImuCalibration, t_s: f64) -> UnitQuaternion<f64> {
    let point = c
        .report
        .history
        .iter()
        .take_while(|h| h.t_s <= t_s)
        .last()
        .expect("updates before t_s");
    UnitQuaternion::from_scaled_axis(Vector3::from(point.rotation_vector))
}

/// The history point of the last update at or before `t_s`.
fn at(c: &PoseImuCalibration, t_s: f64) -> &HistoryPoint {
    c.report
        .history
        .iter()
        .take_while(|h| h.t_s <= t_s)
        .last()
        .expect("updates before t_s")
}

#[test]
fn knocked_sensor_is_flagged_within_five_seconds_and_reestimated() {
    let seeds: Vec<u64> = (200..205).collect();
    let results = par_map(&seeds, |seed| {
        let data = simulate(&knocked_config(seed));
        let c = calibrate::<f64>(&data, &PoseImuOptions::default());
        (seed, data, c)
    });
    for (seed, data, c) in &results {
        let truth = data.final_t_imu_pose().rotation;
        let err = |t: f64| estimate_at(c, t).angle_to(&truth).to_degrees();
        let h = at(c, KNOCK_AT_S + 20.0);
        let axes = (UnitQuaternion::from_scaled_axis(Vector3::from(h.rotation_vector)).inverse()
            * truth)
            .scaled_axis();
        println!(
            "seed {seed}: events {:?}; error +5 s {:.3}, +10 s {:.3}, +20 s {:.3} deg (1-sigma per axis {:.3?} deg), +29 s {:.3}",
            c.report.events.iter().map(|e| (e.t_s, e.kind)).collect::<Vec<_>>(),
            err(KNOCK_AT_S + 5.0),
            err(KNOCK_AT_S + 10.0),
            err(KNOCK_AT_S + 20.0),
            h.sigma_rot_deg,
            err(KNOCK_AT_S + 29.0),
        );
        // Flagged, as a rotation step, within 5 s, and only once.
        let first = c.report.events.first().expect("the knock must be flagged");
        assert_eq!(first.kind, "rotation_step", "seed {seed}");
        assert!(
            first.t_s >= KNOCK_AT_S && first.t_s <= KNOCK_AT_S + 5.0,
            "seed {seed}: flagged at {:.2} s",
            first.t_s
        );
        assert_eq!(
            c.report.events.len(),
            1,
            "seed {seed}: flagged more than once"
        );
        // Re-estimated: 20 s after the knock the estimate has left the old mounting and sits
        // inside its own 3 sigma around the new one.
        for i in 0..3 {
            let e = axes[i].to_degrees().abs();
            assert!(
                e <= 3.0 * h.sigma_rot_deg[i],
                "seed {seed}: axis {i} error {e:.3} deg > 3 sigma"
            );
        }
        assert!(
            err(KNOCK_AT_S + 20.0)
                < 0.5
                    * estimate_at(c, KNOCK_AT_S - 0.1)
                        .angle_to(&truth)
                        .to_degrees()
        );
    }
}

#[test]
fn untouched_sensor_is_never_flagged() {
    let seeds: Vec<u64> = (300..310).collect();
    let events = par_map(&seeds, |seed| {
        let data = simulate(&SimConfig {
            seed,
            ..SimConfig::default()
        });
        calibrate::<f64>(&data, &PoseImuOptions::default())
            .report
            .events
            .len()
    });
    println!("events per unknocked run: {events:?}");
    assert!(events.iter().all(|&n| n == 0), "false alarms: {events:?}");
}
