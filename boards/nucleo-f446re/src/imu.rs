//! The ICM-42688-P on SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI: Arduino D13, D12, D11), chip
//! select PB6 (D10), INT1 on PC7 (D9, EXTI line 7): the interrupt handler stamps each
//! data-ready pulse on the device clock and counts it ([`msreg_icm42688::stamp`]).

use core::cell::{Cell, RefCell};

use cortex_m::interrupt::{free, Mutex};
use embedded_hal_bus::spi::{ExclusiveDevice, NoDelay};
use msreg_icm42688::{DataReady, Icm42688};
use stm32f4xx_hal::gpio::{Input, Output, PushPull, PB6, PC7};
use stm32f4xx_hal::pac::{interrupt, SPI1};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::spi::Spi;

use crate::clock;

/// The SPI device of the IMU.
pub type ImuSpi = ExclusiveDevice<Spi<SPI1>, PB6<Output<PushPull>>, NoDelay>;
/// The driver on it.
pub type Imu = Icm42688<ImuSpi>;
/// The data-ready line.
pub type Int1 = PC7<Input>;

/// SPI clock requested (the HAL takes the nearest lower divider of the 90 MHz APB2:
/// 5.625 MHz; the part allows 24 MHz).
pub const SPI_HZ: u32 = 10_000_000;

static INT1: Mutex<RefCell<Option<Int1>>> = Mutex::new(RefCell::new(None));
static DRDY: Mutex<Cell<DataReady>> = Mutex::new(Cell::new(DataReady {
    stamp_ns: 0,
    count: 0,
}));

/// INT1 (PC7, lines 5-9 share the vector): the time and number of the pulse.
#[interrupt]
fn EXTI9_5() {
    let now = clock::now_ns();
    free(|cs| {
        if let Some(pin) = INT1.borrow(cs).borrow_mut().as_mut() {
            pin.clear_interrupt_pending_bit();
        }
        let cell = DRDY.borrow(cs);
        let count = cell.get().count.wrapping_add(1);
        cell.set(DataReady {
            stamp_ns: now,
            count,
        });
    });
}

/// Hands the configured INT1 pin to the interrupt handler and unmasks EXTI9_5.
pub fn listen(pin: Int1) {
    let irq = pin.interrupt();
    free(|cs| INT1.borrow(cs).replace(Some(pin)));
    // SAFETY: the handler only touches INT1 and DRDY, both ready now.
    unsafe { cortex_m::peripheral::NVIC::unmask(irq) };
}

/// A copy of the latest data-ready pulse (atomic with respect to the handler).
pub fn data_ready() -> DataReady {
    free(|cs| DRDY.borrow(cs).get())
}
