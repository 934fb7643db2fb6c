//! Link firmware: the f32 filter driven over UART0 by `msreg link` (docs/protocol.md).
//! Receives frames into a bounded buffer, applies them in order, streams estimates,
//! diagnostics, alarms and typed error reports back. Bad input is counted, never fatal.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use panic_halt as _;

use msreg_firmware::session::Session;
use msreg_firmware::uart::Uart;
use msreg_protocol::{frame, Deframer, HostMsg, Pushed, HOST_FRAME_MAX};

#[entry]
fn main() -> ! {
    let Some(mut core) = cortex_m::Peripherals::take() else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    // SAFETY: called once, before any interrupt is enabled.
    let mut uart = unsafe { Uart::init(&mut core.SCB) };
    let session = cortex_m::singleton!(: Session = Session::new());
    let deframer = cortex_m::singleton!(: Deframer<HOST_FRAME_MAX> = Deframer::new());
    let (Some(session), Some(deframer)) = (session, deframer) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    hprintln!(
        "msreg link firmware: ready (protocol v{})",
        msreg_protocol::VERSION
    );
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
                Ok(packet) => session.handle(&mut uart, packet),
                Err(e) => session.frame_error(&mut uart, e),
            },
        }
    }
}
