//! Driver of the CMSDK APB UART (QEMU mps2-an386 UART0 at `0x4000_4000`) behind
//! `embedded_io` 0.7 `Read`, `ReadReady` and `Write`, so a board HAL's UART can take its
//! place. Receive is interrupt driven (UART0 RX = IRQ 0) into a bounded [`Ring`]; transmit
//! polls the TX-full flag.
//!
//! Registers: `DATA` +0x00, `STATE` +0x04 (bit 0 TX full, bit 1 RX full, bits 2-3 overrun,
//! write 1 to clear), `CTRL` +0x08 (bit 0 TX enable, bit 1 RX enable, bit 3 RX interrupt),
//! `INTSTATUS/INTCLEAR` +0x0C (bit 1 RX), `BAUDDIV` +0x10.
//!
//! Receive time stamps (clock sync, docs/protocol.md): the interrupt handler stamps the first
//! byte of every frame (a non-zero byte after a delimiter `0x00`, or the stream's first) it
//! stores with the device clock ([`DeviceClock::now_ns`]), tagged with the byte's index in
//! the stream; when the main loop takes that byte out of the ring, [`Uart::frame_start_ns`]
//! returns its stamp. The frame's first byte, not its delimiter: the host stamps the start of
//! what it writes and reads too, so the frame's own transfer time (a UART's serialisation,
//! QEMU's byte-at-a-time receive) is in neither direction's delay. The handler stores a byte
//! only when its own count says the ring has room (a byte it cannot store is dropped and
//! counted, as the ring would), so the indices of both sides never drift apart, and both
//! sides tell a frame's first byte from the same stored sequence.

use core::cell::UnsafeCell;
use core::convert::Infallible;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;

use crate::ring::Ring;
use crate::ticks::DeviceClock;

const UART0: usize = 0x4000_4000;
const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const INTCLEAR: usize = 0x0C;
const BAUDDIV: usize = 0x10;
const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const STATE_OVERRUN: u32 = 0b11 << 2;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_RX_IRQ: u32 = 1 << 3;
const INT_RX: u32 = 1 << 1;

/// Receive ring size, bytes (the host keeps fewer than this in flight).
pub const RX_RING: usize = 4096;

/// Bytes received by the interrupt handler, not yet read.
static RX: Ring<RX_RING> = Ring::new();
/// Bytes the handler stored in [`RX`] (the index of the next one).
static STORED: AtomicU32 = AtomicU32::new(0);
/// Bytes the main loop took out of [`RX`] (counted after the pop).
static TAKEN: AtomicU32 = AtomicU32::new(0);
/// Bytes the handler dropped because [`RX`] was full by its count.
static DROPPED: AtomicU32 = AtomicU32::new(0);
/// Receive stamps of the frames' first bytes waiting in [`RX`].
static STAMPS: StampQueue = StampQueue::new();
/// The last byte the handler stored was a delimiter (or none was stored yet): the next
/// non-zero byte starts a frame.
static STORED_AT_START: AtomicBool = AtomicBool::new(true);

/// Frame-start stamps that may wait (more, e.g. in a burst of tiny frames, are dropped: those
/// frames have no receive stamp).
const STAMPS_MAX: usize = 16;

/// Single-producer (interrupt) single-consumer (main loop) queue of `(byte index, ns)`.
struct StampQueue {
    slots: UnsafeCell<[(u32, u64); STAMPS_MAX]>,
    head: AtomicU32,
    tail: AtomicU32,
}

// SAFETY: the producer writes `slots[head]` then publishes `head`; the consumer reads
// `slots[tail]` then publishes `tail`; no slot is accessed by both at once.
unsafe impl Sync for StampQueue {}

impl StampQueue {
    const fn new() -> Self {
        Self {
            slots: UnsafeCell::new([(0, 0); STAMPS_MAX]),
            head: AtomicU32::new(0),
            tail: AtomicU32::new(0),
        }
    }

    fn push(&self, entry: (u32, u64)) {
        let head = self.head.load(Ordering::Relaxed);
        if head.wrapping_sub(self.tail.load(Ordering::Acquire)) as usize >= STAMPS_MAX {
            return;
        }
        // SAFETY: the slot at `head` is not visible to the consumer until `head` advances.
        unsafe { (*self.slots.get())[head as usize % STAMPS_MAX] = entry };
        self.head.store(head.wrapping_add(1), Ordering::Release);
    }

    /// The stamp of byte `index`, dropping older entries (their bytes are gone).
    fn take(&self, index: u32) -> Option<u64> {
        loop {
            let tail = self.tail.load(Ordering::Relaxed);
            if tail == self.head.load(Ordering::Acquire) {
                return None;
            }
            // SAFETY: the producer does not write this slot until `tail` advances past it.
            let (at, ns) = unsafe { (*self.slots.get())[tail as usize % STAMPS_MAX] };
            let behind = index.wrapping_sub(at);
            if behind > u32::MAX / 2 {
                return None; // a later byte's stamp: keep it
            }
            self.tail.store(tail.wrapping_add(1), Ordering::Release);
            if behind == 0 {
                return Some(ns);
            }
        }
    }
}

/// External interrupts of mps2-an386 used here.
#[derive(Clone, Copy)]
#[repr(u16)]
enum Irq {
    Uart0Rx = 0,
}

// SAFETY: IRQ 0 exists on mps2-an386 (UART0 RX).
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self as u16
    }
}

fn reg(offset: usize) -> *mut u32 {
    (UART0 + offset) as *mut u32
}

fn read_reg(offset: usize) -> u32 {
    // SAFETY: a documented register of the UART0 block.
    unsafe { read_volatile(reg(offset)) }
}

fn write_reg(offset: usize, value: u32) {
    // SAFETY: a documented register of the UART0 block.
    unsafe { write_volatile(reg(offset), value) }
}

/// UART0 RX interrupt: moves every received byte into the ring. The interrupt is cleared
/// before the register is drained, so a byte that lands meanwhile raises it again (clearing
/// afterwards could lose that edge and leave the byte, and the link, stuck).
extern "C" fn uart0_rx_isr() {
    write_reg(INTCLEAR, INT_RX);
    drain_rx_register();
}

fn drain_rx_register() {
    while read_reg(STATE) & STATE_RX_FULL != 0 {
        store(read_reg(DATA) as u8);
    }
    if read_reg(STATE) & STATE_OVERRUN != 0 {
        write_reg(STATE, STATE_OVERRUN);
    }
}

/// Interrupt side: stores `byte` if the ring has room by our count, stamping frame starts.
fn store(byte: u8) {
    let index = STORED.load(Ordering::Relaxed);
    if index.wrapping_sub(TAKEN.load(Ordering::Acquire)) as usize >= RX_RING {
        DROPPED.fetch_add(1, Ordering::Relaxed);
        return;
    }
    if byte != 0 && STORED_AT_START.load(Ordering::Relaxed) {
        STAMPS.push((index, DeviceClock::now_ns()));
    }
    STORED_AT_START.store(byte == 0, Ordering::Relaxed);
    // Cannot drop: the ring's tail is at or past TAKEN, so it holds no more than we count.
    RX.push(byte);
    STORED.store(index.wrapping_add(1), Ordering::Release);
}

/// Main-loop side: the next byte and its index in the stream.
fn take() -> Option<(u8, u32)> {
    let byte = RX.pop()?;
    let index = TAKEN.load(Ordering::Relaxed);
    TAKEN.store(index.wrapping_add(1), Ordering::Release);
    Some((byte, index))
}

/// Vector table in RAM: the core's 16 entries, then the device interrupts. 256-byte
/// alignment satisfies VTOR for up to 64 entries.
#[repr(C, align(256))]
struct Vectors([usize; 16 + 32]);

static mut RAM_VECTORS: Vectors = Vectors([0; 48]);

/// UART0 with interrupt-driven receive.
pub struct Uart {
    /// Receive stamp of the first byte of the last frame begun, if it had one.
    frame_start_ns: Option<u64>,
    /// The last byte taken was a delimiter (or none was taken yet).
    at_start: bool,
}

impl Uart {
    /// Copies the vector table to RAM, installs the RX handler, enables the UART and its RX
    /// interrupt. Call once, before anything else uses the interrupt controller.
    ///
    /// # Safety
    /// Takes over VTOR and UART0; must be called once with interrupts not yet in use.
    pub unsafe fn init(scb: &mut cortex_m::peripheral::SCB) -> Self {
        // SAFETY: the caller's contract above (once, interrupts not yet in use); the table is
        // a static sized for the 48 vectors copied.
        unsafe {
            let table = core::ptr::addr_of_mut!(RAM_VECTORS);
            let flash_table = scb.vtor.read() as *const usize;
            for i in 0..48 {
                (*table).0[i] = read_volatile(flash_table.add(i));
            }
            (*table).0[16 + Irq::Uart0Rx as usize] = uart0_rx_isr as extern "C" fn() as usize;
            scb.vtor.write(table as u32);
            cortex_m::asm::dsb();
            cortex_m::asm::isb();
            write_reg(BAUDDIV, 16);
            write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_IRQ);
            NVIC::unmask(Irq::Uart0Rx);
        }
        Self {
            frame_start_ns: None,
            at_start: true,
        }
    }

    /// Bytes dropped because the receive ring was full, since the last call.
    pub fn take_dropped(&self) -> u32 {
        RX.take_dropped()
            .saturating_add(DROPPED.swap(0, Ordering::Relaxed))
    }

    /// Next received byte, if any (non-blocking). A frame's first byte sets
    /// [`Self::frame_start_ns`].
    pub fn try_read_byte(&mut self) -> Option<u8> {
        let (byte, index) = take()?;
        if byte != 0 && self.at_start {
            self.frame_start_ns = STAMPS.take(index);
        }
        self.at_start = byte == 0;
        Some(byte)
    }

    /// Device clock when the first byte of the frame last begun by [`Self::try_read_byte`]
    /// was received, ns (after its delimiter: the frame just closed); `None` when its stamp
    /// was not kept.
    pub fn frame_start_ns(&self) -> Option<u64> {
        self.frame_start_ns
    }

    /// Sleeps until an interrupt unless a byte is already waiting.
    pub fn wait_for_input(&self) {
        cortex_m::interrupt::free(|_| {
            // Belt and braces: a byte left in the data register is taken here too.
            drain_rx_register();
            if RX.is_empty() {
                // WFI wakes on a pending interrupt even with PRIMASK set; the handler runs
                // once the critical section ends.
                cortex_m::asm::wfi();
            }
        });
    }

    fn write_byte(&mut self, byte: u8) {
        while read_reg(STATE) & STATE_TX_FULL != 0 {}
        write_reg(DATA, u32::from(byte));
    }
}

impl embedded_io::ErrorType for Uart {
    type Error = Infallible;
}

impl embedded_io::Read for Uart {
    /// Blocks until at least one byte is there, then returns what is buffered.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        let mut n = 0;
        while n == 0 {
            while let Some(slot) = buf.get_mut(n) {
                match take() {
                    Some((b, _)) => {
                        *slot = b;
                        n += 1;
                    }
                    None => break,
                }
            }
            if n == 0 {
                self.wait_for_input();
            }
        }
        Ok(n)
    }
}

impl embedded_io::ReadReady for Uart {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!RX.is_empty())
    }
}

impl embedded_io::Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            self.write_byte(b);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
