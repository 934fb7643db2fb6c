//! Instruction counting on the emulated Cortex-M4F with SysTick.
//!
//! QEMU models no cycles, but with `-icount shift=0` its virtual clock advances exactly
//! 1 ns per executed instruction. The mps2-an386 SysTick runs from the 25 MHz core clock,
//! so one SysTick tick is 40 instructions, repeatable to the tick. Without `-icount` the
//! numbers follow the host's wall clock and mean nothing.
//!
//! SysTick is a 24-bit down-counter; one measured section must stay below 2^24 ticks
//! (671 M instructions). No interrupt is used.

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;

/// Instructions per SysTick tick under `-icount shift=0` on mps2-an386 (25 MHz).
pub const INSTRUCTIONS_PER_TICK: u64 = 40;
const MASK: u32 = 0x00FF_FFFF;

/// A free-running SysTick used as an instruction clock.
pub struct InstructionClock {
    _syst: SYST,
}

impl InstructionClock {
    /// Starts SysTick from the core clock with the full 24-bit reload, no interrupt.
    pub fn start(mut syst: SYST) -> Self {
        syst.disable_counter();
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(MASK);
        syst.clear_current();
        syst.enable_counter();
        Self { _syst: syst }
    }

    /// The current counter value (counts down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        SYST::get_current()
    }

    /// Ticks elapsed since `start` (a value of [`now`](Self::now)), modulo 2^24.
    #[inline(always)]
    pub fn ticks_since(&self, start: u32) -> u32 {
        start.wrapping_sub(SYST::get_current()) & MASK
    }

    /// Runs `f` and returns its result and the ticks it took.
    #[inline(always)]
    pub fn measure<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
        let start = self.now();
        let r = f();
        (r, self.ticks_since(start))
    }
}

/// Executes exactly 4000 `nop`s: a known workload that checks [`INSTRUCTIONS_PER_TICK`]
/// (expect 100 ticks, plus the call itself).
#[inline(never)]
pub fn nop_4000() {
    // SAFETY: nops have no effect.
    unsafe { core::arch::asm!(".rept 4000", "nop", ".endr", options(nomem, nostack)) };
}

/// SysTick (and core) clock of mps2-an386, Hz: 40 ns per tick.
pub const CORE_HZ: u64 = 25_000_000;
const NS_PER_TICK: u64 = 1_000_000_000 / CORE_HZ;

/// SysTick wraps (2^24 ticks each) since [`DeviceClock::start`]; incremented only by
/// [`DeviceClock::on_wrap`] (the SysTick exception).
static WRAPS: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

/// The device clock: SysTick from the core clock with its wrap interrupt, extended to 64 bits
/// (2^32 wraps of 0.67 s: 91 years). Monotonic ns since `start`, 40 ns resolution. The link
/// binary's SysTick exception must call [`DeviceClock::on_wrap`]. Under QEMU without
/// `-icount` the core clock follows the host's monotonic clock (QEMU's virtual clock).
pub struct DeviceClock {
    _syst: SYST,
}

impl DeviceClock {
    /// Starts SysTick: full 24-bit reload, core clock, wrap interrupt on.
    pub fn start(mut syst: SYST) -> Self {
        syst.disable_counter();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(MASK);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        Self { _syst: syst }
    }

    /// Counts one wrap; call from the SysTick exception only.
    pub fn on_wrap() {
        WRAPS.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
    }

    /// ns since `start` (callable from interrupts too).
    pub fn now_ns() -> u64 {
        now_ticks().wrapping_mul(NS_PER_TICK)
    }
}

/// Ticks since start: wraps * 2^24 + elapsed in the current period. A wrap whose exception
/// has not run yet is seen as pending (or as the counter jumping up between two reads).
fn now_ticks() -> u64 {
    cortex_m::interrupt::free(|_| {
        let first = SYST::get_current();
        let pending = cortex_m::peripheral::SCB::is_pendst_pending();
        let second = SYST::get_current();
        let mut wraps = u64::from(WRAPS.load(core::sync::atomic::Ordering::Relaxed));
        if pending || second > first {
            wraps += 1;
        }
        (wraps << 24) + u64::from(MASK - (second & MASK))
    })
}
