//! Instruction counts of the f32 filter on the emulated Cortex-M4F: every IMU propagation and
//! every relative-pose update of the embedded sequence is timed with SysTick. Run under
//! `qemu -icount shift=0` (tools/firmware.sh bench), where one tick is 40 instructions.
//!
//! Prints human-readable lines and machine-readable ones for tools/firmware.sh:
//! `BENCH <operation> <calls> <mean instructions> <max instructions>`,
//! `STACK <operation> <bytes>`, `RATE <instructions per second of sensor data>` and
//! `STATES <error states of the filter>`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_halt as _;

use msreg_firmware::scenario::{Event, Scenario, ScenarioConfig};
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
                _ => stack_update = depth,
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
    if selftest::feed(&mut at_rest, &config.spec, &Event::Imu(first)).is_err() {
        return false;
    }
    for _ in 0..20 {
        let (outcome, ticks) = clock.measure(|| at_rest.update_zero_velocity());
        if !outcome.is_ok_and(|r| r.accepted) {
            hprintln!("bench: zero-velocity update not accepted at rest");
            return false;
        }
        zero_velocity.add(ticks);
    }

    propagate.print("propagate");
    update.print("update");
    anchor.print("anchor");
    zero_velocity.print("zero_velocity");
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
    counts.errors == 0
}
