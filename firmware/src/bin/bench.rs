//! Instruction counts of the f32 filter on the emulated Cortex-M4F: every IMU propagation and
//! every relative-pose update of the embedded sequence is timed with SysTick, and so are
//! reprojection updates of the camera-IMU filter with one 6x7 board's corners. Run under
//! `qemu -icount shift=0` (tools/firmware.sh bench), where one tick is 40 instructions.
//!
//! Prints human-readable lines and machine-readable ones for tools/firmware.sh:
//! `BENCH <operation> <calls> <mean instructions> <max instructions>`,
//! `STACK <operation> <bytes>`, `RATE <instructions per second of sensor data>` and
//! `STATES <error states of the filter>`.
#![no_std]
#![no_main]

use core::mem::MaybeUninit;

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_halt as _;

use msreg_estimator::na::{UnitQuaternion, Vector2, Vector3};
use msreg_estimator::{
    CameraImuEkf, CornerObservation, CornerSet, FilterConfig, ImuNoise, ImuSample, InitialState,
    Pose, SOLE_SENSOR, TARGET_FRAME,
};
use msreg_firmware::joint::scenario::{self, JointConfig, JointEvent, JointScenario};
use msreg_firmware::joint::selftest::{JointCounts, JointSetup};
use msreg_firmware::joint::{self, JointFilter, JOINT_STATES};
use msreg_firmware::scenario::{Event, ImuReading, Scenario, ScenarioConfig};
use msreg_firmware::selftest::{self, Filter, RunCounts};
use msreg_firmware::stack;
use msreg_firmware::ticks::{nop_4000, InstructionClock, INSTRUCTIONS_PER_TICK};

/// Sum, maximum and count of the ticks of one kind of call.
#[derive(Clone, Copy, Default)]
struct Tally {
    calls: u64,
    ticks: u64,
    max_ticks: u64,
}

impl Tally {
    fn add(&mut self, ticks: u32) {
        self.calls += 1;
        self.ticks += u64::from(ticks);
        self.max_ticks = self.max_ticks.max(u64::from(ticks));
    }

    fn print(&self, name: &str) {
        let mean = self.ticks * INSTRUCTIONS_PER_TICK / self.calls.max(1);
        let max = self.max_ticks * INSTRUCTIONS_PER_TICK;
        hprintln!(
            "{}: {} calls, {} instructions/call (max {})",
            name,
            self.calls,
            mean,
            max
        );
        hprintln!("BENCH {} {} {} {}", name, self.calls, mean, max);
    }
}

#[entry]
fn main() -> ! {
    let ok = match cortex_m::Peripherals::take() {
        Some(p) => bench(InstructionClock::start(p.SYST)),
        None => false,
    };
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::bkpt();
    }
}

/// The filter's error-state dimension (a type parameter of `Ekf`).
fn error_states<T, const S: usize, const C: usize, const N: usize>(
    _: &msreg_estimator::Ekf<T, S, C, N>,
) -> usize
where
    T: msreg_estimator::Scalar,
{
    N
}

/// Rows and columns of inner corners of the benchmark board (the simulator's 6x7).
const BOARD: (usize, usize) = (6, 7);

/// Reprojection updates of `CameraImuEkf<f32>` at rest, with the 42 corners of a 6x7 board
/// 0.8 m in front of a EuRoC-like pinhole-radtan camera, at their exact projections (so
/// every update passes the gate and the full sequential correction is counted).
fn bench_reprojection(clock: &InstructionClock) -> Option<Tally> {
    let noise = ImuNoise {
        gyro_noise_density: 1.7e-4,
        accel_noise_density: 2.0e-3,
        gyro_random_walk: 1.9e-5,
        accel_random_walk: 3.0e-3,
    };
    let gravity = Vector3::new(0.0, 0.0, 9.81);
    let init = InitialState::<f32, 1>::at_rest(gravity)?
        .with_extrinsic(SOLE_SENSOR, Pose::identity(), 0.01, 0.01)
        .with_time_offset(SOLE_SENSOR, 0.0, 0.005);
    let config = msreg_firmware::filter::device_config(FilterConfig::new(noise));
    let mut ekf = CameraImuEkf::<f32>::new(&config, &init).ok()?;
    let stamp_ns = 1_000_000_000;
    ekf.propagate(&ImuSample {
        stamp_ns,
        gyro: Vector3::zeros(),
        accel: gravity,
    })
    .ok()?;
    let camera = scenario::euroc_camera()?;
    let t_c_t = Pose::new(UnitQuaternion::identity(), Vector3::new(-0.1, -0.12, 0.8));
    let t_g_c = ekf.imu().pose().compose(&ekf.extrinsic(SOLE_SENSOR));
    ekf.init_frame(TARGET_FRAME, t_g_c.compose(&t_c_t), 0.05, 0.05)
        .ok()?;
    let mut corners = [CornerObservation {
        point_in_target: Vector3::zeros(),
        pixel: Vector2::zeros(),
    }; BOARD.0 * BOARD.1];
    for (k, corner) in corners.iter_mut().enumerate() {
        let (r, c) = (k / BOARD.1, k % BOARD.1);
        corner.point_in_target = Vector3::new(r as f32 * 0.04, c as f32 * 0.04, 0.0);
        corner.pixel = camera
            .project(&t_c_t.transform_point(&corner.point_in_target))?
            .pixel;
    }
    let meas = CornerSet {
        stamp_ns,
        corners: &corners,
        pixel_sigma: 0.1,
    };
    let mut tally = Tally::default();
    for _ in 0..10 {
        let (outcome, ticks) =
            clock.measure(|| ekf.update_reprojection(SOLE_SENSOR, TARGET_FRAME, &camera, &meas));
        if !outcome.is_ok_and(|r| r.accepted) {
            return None;
        }
        tally.add(ticks);
    }
    Some(tally)
}

/// The joint layout over its self-test sequence: every call timed by kind, except one
/// relative-pose, image and plane update measured for stack depth instead.
struct JointBench {
    propagate: Tally,
    relative_pose: Tally,
    image: Tally,
    plane: Tally,
    stack: [usize; 3],
    ticks: u64,
    errors: u32,
}

fn bench_joint(clock: &InstructionClock) -> Option<JointBench> {
    let config = JointConfig::default_run();
    let setup = JointSetup {
        config,
        camera: scenario::euroc_camera()?,
    };
    let events = JointScenario::new(config)?;
    let Some(Event::Imu(first)) = Scenario::new(config.base).next() else {
        return None;
    };
    let slot = cortex_m::singleton!(: MaybeUninit<JointFilter> = MaybeUninit::uninit())?;
    let filter = joint::selftest::place_filter(slot, &setup, &first).ok()?;
    let mut b = JointBench {
        propagate: Tally::default(),
        relative_pose: Tally::default(),
        image: Tally::default(),
        plane: Tally::default(),
        stack: [0; 3],
        ticks: 0,
        errors: 0,
    };
    let mut counts = JointCounts::default();
    let (left, dropped) = joint::selftest::drive(filter, events, |filter, event| {
        let slot = match event {
            JointEvent::LidarIncrement(_) => Some((0, counts.relative_poses.calls == 5)),
            JointEvent::Image(_) => Some((1, counts.images.calls == 5)),
            JointEvent::Plane(_) => Some((2, counts.planes.calls == 5)),
            JointEvent::Imu(_) | JointEvent::LidarAnchor { .. } | JointEvent::BadPlane { .. } => {
                None
            }
        };
        let outcome = match slot {
            Some((k, true)) => {
                let (outcome, depth) =
                    stack::depth_of(|| joint::selftest::feed(filter, &setup, event));
                b.stack[k] = depth;
                outcome
            }
            Some((_, false)) | None => {
                let (outcome, ticks) =
                    clock.measure(|| joint::selftest::feed(filter, &setup, event));
                b.ticks += u64::from(ticks);
                let tally = match event {
                    JointEvent::Imu(_) => Some(&mut b.propagate),
                    JointEvent::LidarIncrement(_) => Some(&mut b.relative_pose),
                    JointEvent::Image(_) => Some(&mut b.image),
                    JointEvent::Plane(_) => Some(&mut b.plane),
                    JointEvent::LidarAnchor { .. } | JointEvent::BadPlane { .. } => None,
                };
                if let Some(t) = tally {
                    t.add(ticks);
                }
                outcome
            }
        };
        counts.record(event, &outcome);
    });
    let c = &counts;
    b.errors = c.errors
        + left as u32
        + dropped
        + [c.relative_poses, c.images, c.planes]
            .iter()
            .map(|t| t.calls - t.accepted)
            .sum::<u32>();
    Some(b)
}

fn print_joint(b: &JointBench) {
    b.propagate.print("joint_propagate");
    b.relative_pose.print("joint_update");
    b.image.print("joint_image");
    b.plane.print("joint_plane");
    hprintln!("STACK joint_update {}", b.stack[0]);
    hprintln!("STACK joint_image {}", b.stack[1]);
    hprintln!("STACK joint_plane {}", b.stack[2]);
    let seconds = JointConfig::default_run().base.duration_ns as f32 * 1e-9;
    let rate = (b.ticks * INSTRUCTIONS_PER_TICK) as f32 / seconds;
    hprintln!(
        "joint total (timed calls): {:.1} M instructions/s; {} errors or rejected updates",
        rate * 1e-6,
        b.errors
    );
    hprintln!("RATE_JOINT {}", rate as u64);
    hprintln!("STATES_JOINT {}", JOINT_STATES);
}

fn bench(clock: InstructionClock) -> bool {
    // 4000 nops + call overhead must read 100 ticks; anything else means QEMU is not running
    // with -icount shift=0 and the numbers would be wall-clock noise.
    let ((), calibration) = clock.measure(nop_4000);
    hprintln!("calibration: 4000 nops = {} SysTick ticks", calibration);
    if calibration != 100 {
        hprintln!("bench: not running under -icount shift=0 (expected 100 ticks): FAILED");
        return false;
    }

    let config = ScenarioConfig::default_run();
    let mut events = Scenario::new(config).peekable();
    let Some(Event::Imu(first)) = events.peek().copied() else {
        return false;
    };
    let Ok(filter) = selftest::new_filter(&config, &first) else {
        hprintln!("bench: filter construction failed");
        return false;
    };
    let Some(filter) = cortex_m::singleton!(: Filter = filter) else {
        return false;
    };

    let (mut propagate, mut update, mut anchor) =
        (Tally::default(), Tally::default(), Tally::default());
    let (mut stack_propagate, mut stack_update) = (0, 0);
    let mut counts = RunCounts::default();
    for (i, event) in events.enumerate() {
        // One call of each kind is measured for stack depth instead of time.
        let stack_probe = i == 200 || (matches!(event, Event::Increment(_)) && counts.updates == 5);
        let outcome = if stack_probe {
            let (outcome, depth) = stack::depth_of(|| selftest::feed(filter, &config.spec, &event));
            match event {
                Event::Imu(_) => stack_propagate = depth,
                Event::Anchor { .. } | Event::Increment(_) => stack_update = depth,
            }
            outcome
        } else {
            let (outcome, ticks) = clock.measure(|| selftest::feed(filter, &config.spec, &event));
            match event {
                Event::Imu(_) => propagate.add(ticks),
                Event::Anchor { .. } => anchor.add(ticks),
                Event::Increment(_) => update.add(ticks),
            }
            outcome
        };
        counts.record(&event, &outcome);
    }

    // Zero-velocity updates (9-dof) on a second filter at rest at the first sample, so the
    // gate accepts them and the full update (correction, Joseph form) is what is counted.
    let mut zero_velocity = Tally::default();
    let Ok(mut at_rest) = selftest::new_filter(&config, &first) else {
        return false;
    };
    // A second reading one IMU period on (the same one) gives the stream its period, which
    // the update's per-sample noise refers to; the filter still stands at the first.
    let second = ImuReading {
        stamp_ns: first.stamp_ns + config.imu_period_ns,
        ..first
    };
    for sample in [first, second] {
        if selftest::feed(&mut at_rest, &config.spec, &Event::Imu(sample)).is_err() {
            return false;
        }
    }
    for k in 0..20 {
        let (outcome, ticks) = clock.measure(|| at_rest.update_zero_velocity());
        if !outcome.is_ok_and(|r| r.accepted) {
            hprintln!(
                "bench: zero-velocity update {} not accepted at rest: {:?}",
                k,
                outcome.map(|r| (r.nis, r.threshold))
            );
            return false;
        }
        zero_velocity.add(ticks);
    }

    let Some(reprojection) = bench_reprojection(&clock) else {
        hprintln!("bench: reprojection update failed or was not accepted");
        return false;
    };

    propagate.print("propagate");
    update.print("update");
    anchor.print("anchor");
    zero_velocity.print("zero_velocity");
    reprojection.print("reprojection");
    hprintln!("STACK propagate {}", stack_propagate);
    hprintln!("STACK update {}", stack_update);
    let total = (propagate.ticks + update.ticks + anchor.ticks) * INSTRUCTIONS_PER_TICK;
    let seconds = config.duration_ns as f32 * 1e-9;
    let rate = total as f32 / seconds;
    hprintln!(
        "total: {} instructions for {} s of data = {:.1} M instructions/s; {} errors",
        total,
        seconds,
        rate * 1e-6,
        counts.errors
    );
    hprintln!("RATE {}", rate as u64);
    hprintln!("STATES {}", error_states(filter));
    let Some(joint) = bench_joint(&clock) else {
        hprintln!("bench: joint layout setup failed");
        return false;
    };
    print_joint(&joint);
    counts.errors == 0 && joint.errors == 0
}
