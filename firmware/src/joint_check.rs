//! The joint-layout part of the self-test binary (a module of `main.rs`, not of the
//! library): builds `JointEkf<f32>` in `.bss`, runs it over the joint sequence and prints
//! the report and the checks.

use core::mem::MaybeUninit;

use cortex_m_semihosting::hprintln;

use msreg_firmware::joint::scenario::{self, JointConfig, JointScenario};
use msreg_firmware::joint::selftest::{self, JointSetup, SensorResult};
use msreg_firmware::joint::{
    self, JointFilter, JointReport, JOINT_COVARIANCE_BYTES, JOINT_FILTER_BYTES, JOINT_STATES,
    MSREG_JOINT_FILTER_BYTES,
};
use msreg_firmware::scenario::{Event, Scenario};
use msreg_firmware::selftest::rpy_deg;
use msreg_firmware::stack;

/// Runs the joint self-test; true if every check passed.
pub fn run(config: &JointConfig) -> bool {
    // Read through black_box so the symbol stays in the ELF for `firmware.sh size`.
    let symbol = *core::hint::black_box(&MSREG_JOINT_FILTER_BYTES);
    hprintln!(
        "joint layout: JointEkf<f32> = Ekf<f32, 2, 4, {}, 1>: {} B (covariance {} B), \
         compile-time constant (symbol MSREG_JOINT_FILTER_BYTES = {})",
        JOINT_STATES,
        JOINT_FILTER_BYTES,
        JOINT_COVARIANCE_BYTES,
        symbol
    );
    let (Some(camera), Some(mut events)) = (scenario::euroc_camera(), JointScenario::new(*config))
    else {
        hprintln!("joint: camera model invalid: FAILED");
        return false;
    };
    let setup = JointSetup {
        config: *config,
        camera,
    };
    let filter = build(&setup);
    let after_build = stack::high_water_bytes();
    let Some(filter) = filter else {
        return false;
    };
    let report = joint::run(&setup, filter, &mut events);
    hprintln!(
        "joint stack: painted peak of the self-test so far {} B after the construction, {} B \
         after the run",
        after_build,
        stack::high_water_bytes()
    );
    print_report(config, &report);
    let checks = report.checks(config);
    for (name, ok) in checks.items {
        hprintln!("check: {}: {}", name, if ok { "ok" } else { "FAILED" });
    }
    checks.all_passed()
}

/// The joint filter in `.bss` (`cortex_m::singleton!`), at rest at the sequence's first
/// IMU sample. Out of line, so that the construction's temporaries are off the stack before
/// the run starts.
#[inline(never)]
fn build(setup: &JointSetup) -> Option<&'static mut JointFilter> {
    let Some(Event::Imu(first)) = Scenario::new(setup.config.base).next() else {
        hprintln!("joint sequence does not start with an IMU sample: FAILED");
        return None;
    };
    let Some(slot) = cortex_m::singleton!(: MaybeUninit<JointFilter> = MaybeUninit::uninit())
    else {
        hprintln!("joint filter storage already taken: FAILED");
        return None;
    };
    match selftest::place_filter(slot, setup, &first) {
        Ok(filter) => Some(filter),
        Err(e) => {
            hprintln!("joint filter construction failed: {}", e);
            None
        }
    }
}

fn print_report(config: &JointConfig, r: &JointReport) {
    let c = &r.counts;
    hprintln!(
        "joint sequence: {} s, {} IMU samples at 400 Hz, {} LiDAR increments at 10 Hz, {} images \
         of {} corners at 20 Hz, {} board planes at 10 Hz; {} corners outside the image, {} dropped",
        config.base.duration_ns as f32 * 1e-9,
        config.base.imu_count(),
        config.increment_count(),
        config.image_count(),
        scenario::CORNERS,
        config.plane_count(),
        c.corners_outside,
        r.dropped
    );
    hprintln!(
        "joint processed: {} IMU samples, {} anchor, relative poses {}/{}, images {}/{}, \
         planes {}/{} (accepted/processed), {} errors, {} never due",
        c.imu_samples,
        c.anchors,
        c.relative_poses.accepted,
        c.relative_poses.calls,
        c.images.accepted,
        c.images.calls,
        c.planes.accepted,
        c.planes.calls,
        c.errors,
        r.left
    );
    if let Some(e) = c.first_error {
        hprintln!("joint first error: {}", e);
    }
    print_sensor("LiDAR", &r.lidar, 0.0);
    print_sensor("camera", &r.camera, config.camera_time_offset);
    if let Some(b) = r.board {
        hprintln!(
            "board pose error / sigma: rotation ({:.2}, {:.2}, {:.2}), position ({:.2}, {:.2}, {:.2})",
            b[0],
            b[1],
            b[2],
            b[3],
            b[4],
            b[5]
        );
    }
    hprintln!(
        "joint covariance: max |P - P^T| = {:.1e}, min diagonal {:.2e}, finite: {}",
        r.covariance.max_asymmetry,
        r.covariance.min_diagonal,
        r.covariance.finite
    );
}

fn print_sensor(name: &str, r: &SensorResult, true_offset: f32) {
    let [er, ep, ey] = rpy_deg(&r.estimate.rotation);
    let [tr, tp, ty] = rpy_deg(&r.truth.rotation);
    hprintln!(
        "{} rpy [deg]: estimate ({:.3}, {:.3}, {:.3}) truth ({:.3}, {:.3}, {:.3})",
        name,
        er,
        ep,
        ey,
        tr,
        tp,
        ty
    );
    let n = &r.normalized;
    hprintln!(
        "{} error: rotation {:.3} -> {:.3} deg, translation {:.4} -> {:.4} m; error / sigma \
         ({:.2}, {:.2}, {:.2}, {:.2}, {:.2}, {:.2}), NEES {:.2} (6 dof); t_d {:.3} ms (truth {:.3}, \
         error / sigma {:.2})",
        name,
        r.initial_error.rotation.to_degrees(),
        r.final_error.rotation.to_degrees(),
        r.initial_error.translation,
        r.final_error.translation,
        n[0],
        n[1],
        n[2],
        n[3],
        n[4],
        n[5],
        r.nees,
        r.time_offset * 1e3,
        true_offset * 1e3,
        r.time_offset_normalized
    );
}
