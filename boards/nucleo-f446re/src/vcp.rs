//! USART2, wired to the ST-LINK's virtual COM port on the NUCLEO-64 (PA2 TX, PA3 RX), behind
//! `embedded_io` 0.7 `Read`, `ReadReady` and `Write` (the traits the firmware's link session
//! writes to; stm32f4xx-hal 0.23 implements embedded-io 0.6 only). Receive is interrupt
//! driven (USART2 RXNE) into the firmware's bounded [`Ring`], as QEMU's UART0 driver does;
//! transmit blocks on the HAL's `Tx`.
//!
//! Receive stamps: the handler stamps the first byte of each frame (a non-zero byte after a
//! delimiter `0x00`, or the stream's first) on the device clock as it arrives, numbered; the
//! main loop counts the frame starts it takes out of the ring and, once the frame's delimiter
//! is taken, [`Vcp::frame_start_ns`] returns that frame's stamp (the session's `rx_ns`, `t2`
//! of the clock sync, docs/protocol.md: the frame's start, as the host stamps the start of
//! what it writes, so the frame's serialisation time is in neither direction's delay),
//! unaffected by how long the loop was busy. The last [`STAMPS`] stamps are kept; when the
//! ring runs empty the loop's count is re-aligned with the handler's (a byte dropped in a
//! full ring may have started a frame).

use core::cell::RefCell;
use core::convert::Infallible;

use cortex_m::interrupt::{free, Mutex};
use msreg_firmware::ring::Ring;
use stm32f4xx_hal::pac::{self, interrupt, USART2};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{Rx, Tx};

/// Receive ring size, bytes: the firmware's `uart::RX_RING`, which the link's Hello
/// announces to the host.
pub const RX_RING: usize = msreg_firmware::uart::RX_RING;

/// Link speed. The host opens the port at 115200 (`host/src/link/port.rs`).
pub const BAUD: u32 = 115_200;

static RX: Ring<RX_RING> = Ring::new();
static RX_HALF: Mutex<RefCell<Option<Rx<USART2>>>> = Mutex::new(RefCell::new(None));

/// Frame-start stamps kept (frames that may wait in the ring with their receive time).
pub const STAMPS: usize = 16;

/// The handler's frame starts: how many arrived, `(number, ns)` of the last [`STAMPS`], and
/// whether the last byte was a delimiter (the next non-zero byte starts a frame).
struct FrameStarts {
    count: u32,
    stamps: [(u32, u64); STAMPS],
    at_start: bool,
}

static STARTS: Mutex<RefCell<FrameStarts>> = Mutex::new(RefCell::new(FrameStarts {
    count: 0,
    stamps: [(0, 0); STAMPS],
    at_start: true,
}));

/// USART2 RXNE: moves every received byte into the ring. A receive error (overrun,
/// framing, noise) is cleared by the read and the byte lost; the session sees the gap as a
/// frame error.
#[interrupt]
fn USART2() {
    free(|cs| {
        if let Some(rx) = RX_HALF.borrow(cs).borrow_mut().as_mut() {
            loop {
                match rx.read() {
                    Ok(b) => {
                        let mut d = STARTS.borrow(cs).borrow_mut();
                        if b != 0 && d.at_start {
                            d.count = d.count.wrapping_add(1);
                            let n = d.count;
                            d.stamps[n as usize % STAMPS] = (n, crate::clock::now_ns());
                        }
                        d.at_start = b == 0;
                        RX.push(b);
                    }
                    Err(nb::Error::WouldBlock) => break,
                    Err(nb::Error::Other(_)) => {}
                }
            }
        }
    });
}

/// The link's UART.
pub struct Vcp {
    tx: Tx<USART2>,
    /// Frame starts taken out of the ring.
    taken: u32,
    /// The last byte taken was a delimiter (or none was taken yet).
    at_start: bool,
    /// Receive stamp of the frame being taken, if it was kept.
    current: Option<u64>,
    /// Receive stamp of the last complete frame taken, until asked for.
    frame_start: Option<u64>,
}

impl Vcp {
    /// Takes the two halves of the configured USART2, keeps the receiver for the interrupt
    /// and unmasks it.
    pub fn new(tx: Tx<USART2>, mut rx: Rx<USART2>) -> Self {
        rx.listen();
        free(|cs| RX_HALF.borrow(cs).replace(Some(rx)));
        // SAFETY: the handler only touches RX_HALF and RX, both ready now.
        unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART2) };
        Self {
            tx,
            taken: 0,
            at_start: true,
            current: None,
            frame_start: None,
        }
    }

    /// Bytes dropped because the receive ring was full, since the last call.
    pub fn take_dropped(&self) -> u32 {
        RX.take_dropped()
    }

    /// Next received byte, if any (non-blocking).
    pub fn try_read_byte(&mut self) -> Option<u8> {
        let b = RX.pop()?;
        free(|cs| {
            let d = STARTS.borrow(cs).borrow();
            if b != 0 && self.at_start {
                self.taken = self.taken.wrapping_add(1);
                let (n, ns) = d.stamps[self.taken as usize % STAMPS];
                self.current = (n == self.taken).then_some(ns);
            }
            if b == 0 {
                self.frame_start = self.current.take();
            }
            self.at_start = b == 0;
            if RX.is_empty() {
                self.taken = d.count;
                self.at_start = d.at_start;
            }
        });
        Some(b)
    }

    /// Device-clock time at which the first byte of the last complete frame taken arrived,
    /// if its stamp was kept (`None` after more than [`STAMPS`] frames queued behind it).
    pub fn frame_start_ns(&mut self) -> Option<u64> {
        self.frame_start.take()
    }

    /// True when a received byte waits.
    pub fn has_input(&self) -> bool {
        !RX.is_empty()
    }
}

impl embedded_io::ErrorType for Vcp {
    type Error = Infallible;
}

impl embedded_io::Read for Vcp {
    /// Blocks until at least one byte is there, then returns what is buffered.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        let mut n = 0;
        while n == 0 {
            while let Some(slot) = buf.get_mut(n) {
                match RX.pop() {
                    Some(b) => {
                        *slot = b;
                        n += 1;
                    }
                    None => break,
                }
            }
            if n == 0 {
                cortex_m::asm::wfi();
            }
        }
        Ok(n)
    }
}

impl embedded_io::ReadReady for Vcp {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!RX.is_empty())
    }
}

impl embedded_io::Write for Vcp {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            // The HAL's error type for a transmit is Infallible in practice; a refused byte
            // is retried until the data register is empty.
            while self.tx.write(b).is_err() {}
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        while self.tx.flush().is_err() {}
        Ok(())
    }
}
