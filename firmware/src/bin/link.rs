//! Link firmware: the f32 filter driven over UART0 by `msreg link` (docs/protocol.md).
//! Receives frames into a bounded buffer, applies them in order, streams estimates,
//! diagnostics, alarms and typed error reports back. Bad input is counted, never fatal.
//! Logs with `defmt` over semihosting (QEMU's stdout; `msreg link log` decodes it), including
//! its RAM use (statics + painted stack peak) at boot and, when the peak grew, after a Status.
#![no_std]
#![no_main]

use core::ptr::addr_of_mut;

use cortex_m_rt::{entry, exception};
use defmt_semihosting as _;
use panic_halt as _;

use msreg_firmware::session::Session;
use msreg_firmware::stack;
use msreg_firmware::ticks::DeviceClock;
use msreg_firmware::uart::Uart;
use msreg_protocol::{frame, Deframer, HostMsg, Pushed, HOST_FRAME_MAX};

/// The session (filter, pose queue, counters) and the frame buffer, initialised at compile
/// time: `cortex_m::singleton!` would build each on the stack first (a 40 KB boot peak).
static mut SESSION: Session = Session::new();
static mut DEFRAMER: Deframer<HOST_FRAME_MAX> = Deframer::new();

/// Logs the RAM in use: statics plus the deepest stack since boot (painted), against the
/// 64 KiB target of docs/benchmarks.md; only when the peak grew since `logged_peak` (a
/// burst of status requests must not flood the log).
fn log_ram(logged_peak: &mut u32) {
    let statics = stack::static_bytes() as u32;
    let peak = stack::high_water_bytes() as u32;
    if peak <= *logged_peak {
        return;
    }
    *logged_peak = peak;
    defmt::info!(
        "ram: static {=u32} B + stack peak {=u32} B = {=u32} B (target {=u32} B)",
        statics,
        peak,
        statics + peak,
        64 * 1024
    );
}

/// SysTick wrapped (every 2^24 core ticks, 0.67 s): extends the device clock.
#[exception]
fn SysTick() {
    DeviceClock::on_wrap();
}

#[entry]
fn main() -> ! {
    let Some(mut core) = cortex_m::Peripherals::take() else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    stack::paint();
    // SAFETY: called once, before any interrupt is enabled.
    let mut uart = unsafe { Uart::init(&mut core.SCB) };
    // The device clock (clock sync): SysTick with its wrap interrupt, after the vector table
    // moved to RAM (its SysTick entry is this binary's handler below).
    let _clock = DeviceClock::start(core.SYST);
    // SAFETY: `main` runs once and is the only user of both statics (the UART interrupt
    // touches neither), so these are the only references ever made.
    let (session, deframer) =
        unsafe { (&mut *addr_of_mut!(SESSION), &mut *addr_of_mut!(DEFRAMER)) };
    defmt::info!(
        "msreg link firmware ready: protocol v{=u16}, rx ring {=u32} B, frames up to {=u32} B",
        msreg_protocol::VERSION,
        msreg_firmware::uart::RX_RING as u32,
        HOST_FRAME_MAX as u32
    );
    let mut logged_peak = 0;
    log_ram(&mut logged_peak);
    session.announce(&mut uart);
    loop {
        let dropped = uart.take_dropped();
        session.overrun(&mut uart, dropped);
        let Some(byte) = uart.try_read_byte() else {
            uart.wait_for_input();
            continue;
        };
        match deframer.push(byte) {
            Pushed::Pending => {}
            Pushed::Oversize => {
                session.frame_error(&mut uart, msreg_protocol::FrameError::Oversize);
            }
            Pushed::Frame(f) => match frame::decode::<HostMsg>(f) {
                Ok(packet) => {
                    let status_request = matches!(packet.msg, HostMsg::GetStatus);
                    let rx_ns = uart.frame_start_ns().unwrap_or_else(DeviceClock::now_ns);
                    session.handle(&mut uart, packet, rx_ns, DeviceClock::now_ns);
                    if status_request {
                        log_ram(&mut logged_peak);
                    }
                }
                Err(e) => session.frame_error(&mut uart, e),
            },
        }
    }
}
