//! Stack high-water mark by painting: fill the unused stack with a pattern early in `main`,
//! later find the deepest word that was overwritten. Uses cortex-m-rt's `_stack_start` (top
//! of the stack) and `_stack_end` (end of the statics, the lowest address the stack may use).

use core::ptr::{addr_of, read_volatile, write_volatile};

const PAINT: u32 = 0x5AFE_C0DE;
/// Words just below the current stack pointer that are left unpainted (the painter's own
/// frame and anything an interrupt might push meanwhile).
const GUARD_BYTES: usize = 256;

extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
    /// Start of `.data`, the first byte of RAM the statics use.
    static __sdata: u32;
    /// `memory.x`: the stack budget; the link fails if the statics leave less RAM than this.
    static STACK_RESERVE: u8;
}

fn top() -> usize {
    // Only the address of the linker symbol is taken, never its value.
    addr_of!(_stack_start) as usize
}

fn bottom() -> usize {
    addr_of!(_stack_end) as usize
}

/// RAM taken by the statics (`.data`, `.bss`, `.uninit`), bytes.
pub fn static_bytes() -> usize {
    bottom() - addr_of!(__sdata) as usize
}

/// The stack budget of `memory.x` (`STACK_RESERVE`), bytes.
pub fn budget_bytes() -> usize {
    // An absolute linker symbol: its address is its value.
    addr_of!(STACK_RESERVE) as usize
}

/// Bytes available to the stack: from the end of the statics to the top of RAM.
pub fn available_bytes() -> usize {
    top() - bottom()
}

/// Fills the stack below the current frame with the pattern. Call once, early in `main`.
#[inline(never)]
pub fn paint() {
    let limit = cortex_m::register::msp::read() as usize - GUARD_BYTES;
    let mut p = bottom();
    while p < limit {
        // SAFETY: [bottom, limit) is RAM reserved for the stack and below every live frame.
        unsafe { write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// The deepest stack use since [`paint`], in bytes from the top of RAM.
pub fn high_water_bytes() -> usize {
    let mut p = bottom();
    // SAFETY: reads of RAM reserved for the stack, word-aligned.
    while p < top() && unsafe { read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    top() - p
}

/// Runs `f` and returns its result and the stack it used below the caller's frame, in bytes
/// (calls using less than the painter's guard of 256 B read as up to 256 B too small).
#[inline(never)]
pub fn depth_of<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let sp = cortex_m::register::msp::read() as usize;
    paint();
    let r = f();
    let used_before = top() - sp;
    (r, high_water_bytes().saturating_sub(used_before))
}
