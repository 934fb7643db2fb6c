//! The device clock: the Cortex-M4 cycle counter (DWT `CYCCNT`, 180 MHz) extended to 64
//! bits, in nanoseconds since boot. The IMU's data-ready stamps and the filter's time are on
//! this clock. `CYCCNT` wraps every 23.9 s: [`now_ns`] must run at least that often, which
//! the SysTick handler (every 93 ms, `main.rs`) guarantees.

use core::cell::Cell;

use cortex_m::interrupt::{free, Mutex};
use cortex_m::peripheral::DWT;

/// Core clock, Hz (`main.rs` sets it).
pub const SYSCLK_HZ: u32 = 180_000_000;
/// ns per cycle as a fraction: 1e9 / 180e6 = 50 / 9.
const NS_NUM: u64 = 50;
const NS_DEN: u64 = 9;
const _: () = assert!(NS_NUM * SYSCLK_HZ as u64 == NS_DEN * 1_000_000_000);

/// Last `CYCCNT` seen and the wraps so far.
static STATE: Mutex<Cell<(u32, u32)>> = Mutex::new(Cell::new((0, 0)));

/// Nanoseconds since the cycle counter started (monotonic; callable from any context).
pub fn now_ns() -> u64 {
    free(|cs| {
        let cell = STATE.borrow(cs);
        let (last, mut wraps) = cell.get();
        let now = DWT::cycle_count();
        if now < last {
            wraps = wraps.wrapping_add(1);
        }
        cell.set((now, wraps));
        let cycles = (u64::from(wraps) << 32) | u64::from(now);
        cycles * NS_NUM / NS_DEN
    })
}
