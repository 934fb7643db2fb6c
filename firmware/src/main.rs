//! Firmware self-test: runs the f32 filter over the embedded sensor sequence, reports through
//! semihosting and exits QEMU with success only if every check passed.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_halt as _;

mod joint_check;

use msreg_firmware::generator_check::dead_reckon;
use msreg_firmware::joint::scenario::JointConfig;
use msreg_firmware::scenario::{Event, Scenario, ScenarioConfig};
use msreg_firmware::selftest::{self, rpy_deg, Filter, SelfTestReport};
use msreg_firmware::stack;

#[entry]
fn main() -> ! {
    stack::paint();
    hprintln!("msreg firmware self-test (thumbv7em-none-eabihf, f32)");
    let config = ScenarioConfig::default_run();
    let passed = check_generator(&config)
        && check_filter(&config)
        && joint_check::run(&JointConfig::default_run())
        && check_stack();
    if passed {
        hprintln!("firmware self-test: PASS");
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        hprintln!("firmware self-test: FAIL");
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::bkpt();
    }
}

/// The embedded sequence is consistent (dead reckoning lands on the analytic trajectory).
fn check_generator(config: &ScenarioConfig) -> bool {
    let dr = dead_reckon(config);
    let ok = dr.passed() && u64::from(dr.samples) == config.imu_count();
    hprintln!(
        "sequence: {} s, {} IMU samples at 400 Hz, {} poses at 10 Hz; noise-free dead reckoning \
         drifts {:.1e} rad, {:.1e} m: {}",
        config.duration_ns as f32 * 1e-9,
        config.imu_count(),
        config.pose_count(),
        dr.rotation_error,
        dr.position_error,
        if ok { "ok" } else { "FAILED" }
    );
    ok
}

/// The filter converges on the sequence and stays healthy.
fn check_filter(config: &ScenarioConfig) -> bool {
    let mut events = Scenario::new(*config).peekable();
    let Some(Event::Imu(first)) = events.peek().copied() else {
        hprintln!("sequence does not start with an IMU sample: FAILED");
        return false;
    };
    // The filter lives in .bss (cortex_m::singleton!), so `size` shows its footprint.
    let filter = match selftest::new_filter(config, &first) {
        Ok(f) => cortex_m::singleton!(: Filter = f),
        Err(e) => {
            hprintln!("filter construction failed: {}", e);
            return false;
        }
    };
    let Some(filter) = filter else {
        hprintln!("filter storage already taken: FAILED");
        return false;
    };
    let report = selftest::run(config, filter, events);
    print_report(&report);
    let checks = report.checks(config);
    for (name, ok) in checks.items {
        hprintln!("check: {}: {}", name, if ok { "ok" } else { "FAILED" });
    }
    checks.all_passed()
}

/// The deepest stack use so far fits the budget of memory.x.
fn check_stack() -> bool {
    let (used, budget) = (stack::high_water_bytes(), stack::budget_bytes());
    let ok = used <= budget;
    hprintln!(
        "stack: {} B used, budget {} B (memory.x STACK_RESERVE), {} B available: {}",
        used,
        budget,
        stack::available_bytes(),
        if ok { "ok" } else { "FAILED" }
    );
    ok
}

fn print_report(r: &SelfTestReport) {
    let c = &r.counts;
    hprintln!(
        "processed: {} IMU samples, {} anchor, {} relative-pose updates ({} accepted), {} errors",
        c.imu_samples,
        c.anchors,
        c.updates,
        c.accepted,
        c.errors
    );
    if let Some(e) = c.first_error {
        hprintln!("first error: {}", e);
    }
    let [er, ep, ey] = rpy_deg(&r.estimate.rotation);
    let [tr, tp, ty] = rpy_deg(&r.truth.rotation);
    hprintln!(
        "extrinsic rotation rpy [deg]: estimate ({:.3}, {:.3}, {:.3}) truth ({:.3}, {:.3}, {:.3})",
        er,
        ep,
        ey,
        tr,
        tp,
        ty
    );
    let (e, t) = (r.estimate.translation, r.truth.translation);
    hprintln!(
        "extrinsic translation [m]: estimate ({:.4}, {:.4}, {:.4}) truth ({:.4}, {:.4}, {:.4})",
        e.x,
        e.y,
        e.z,
        t.x,
        t.y,
        t.z
    );
    let (sr, st) = r.sigma;
    hprintln!(
        "error: rotation {:.3} -> {:.3} deg (1-sigma {:.3}, {:.3}, {:.3}), translation \
         {:.4} -> {:.4} m (1-sigma {:.4}, {:.4}, {:.4})",
        r.initial_error.rotation.to_degrees(),
        r.final_error.rotation.to_degrees(),
        sr.x.to_degrees(),
        sr.y.to_degrees(),
        sr.z.to_degrees(),
        r.initial_error.translation,
        r.final_error.translation,
        st.x,
        st.y,
        st.z
    );
    hprintln!(
        "covariance: max |P - P^T| = {:.1e}, min diagonal {:.2e}, finite: {}",
        r.covariance.max_asymmetry,
        r.covariance.min_diagonal,
        r.covariance.finite
    );
}
