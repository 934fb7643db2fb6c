//! msreg on the NUCLEO-F446RE (STM32F446RE, Cortex-M4F at 180 MHz): the firmware's link
//! session over the ST-LINK virtual COM port (USART2, 115200 baud), an ICM-42688-P on SPI1
//! read through `msreg-icm42688` at its data-ready interrupt, defmt over RTT.
//!
//! Boot: clocks (HSI 16 MHz -> PLL 180 MHz, over-drive), device clock (DWT), the IMU
//! (WHO_AM_I, soft reset, self-test, configuration: 500 Hz, +-1000 deg/s, +-8 g), then the
//! link's Hello. The loop applies host frames to the session as the QEMU `link` binary
//! does, and after each data-ready pulse reads the IMU's FIFO and feeds the samples to the
//! session ([`feed`]). A missing IMU is logged and the link runs without it.
#![no_std]
#![no_main]

mod clock;
mod feed;
mod imu;
mod vcp;

use core::ptr::addr_of_mut;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{entry, exception};
use defmt_rtt as _;
use embedded_hal_bus::spi::ExclusiveDevice;
use msreg_firmware::session::Session;
use msreg_icm42688::{Config, Icm42688, Sample, SelfTestReport};
use msreg_protocol::{frame, Deframer, HostMsg, Pushed, HOST_FRAME_MAX};
use panic_probe as _;
use stm32f4xx_hal::dwt::DwtExt;
use stm32f4xx_hal::gpio::Edge;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Config as RccConfig;
use stm32f4xx_hal::serial::{config::Config as SerialConfig, Serial};
use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};

use crate::imu::Imu;
use crate::vcp::Vcp;

/// The session and the frame buffer, initialised at compile time (as `link.rs`).
static mut SESSION: Session = Session::new();
static mut DEFRAMER: Deframer<HOST_FRAME_MAX> = Deframer::new();

/// Device time between two IMU log lines.
const IMU_LOG_PERIOD_NS: u64 = 5_000_000_000;

/// SysTick: keeps the device clock's 64-bit extension current while the core sleeps.
#[exception]
fn SysTick() {
    clock::now_ns();
}

/// What the IMU side did since boot.
#[derive(Default)]
struct ImuStats {
    bursts: u32,
    samples: u32,
    fed: u32,
    invalid: u32,
    corrupt: u32,
    bad_count: u32,
    errors: u32,
    /// Pulse count at the last burst.
    last_pulse: u32,
    last_log_ns: u64,
}

fn log_self_test(r: &SelfTestReport) {
    for (name, a) in [
        "gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z",
    ]
    .iter()
    .zip(r.gyro.iter().chain(&r.accel))
    {
        defmt::info!(
            "imu self-test {=str}: code {=u8}, response {=f32} LSB, factory {=f32} LSB, ratio {=f32}: {=str}",
            name,
            a.code,
            a.response_lsb,
            a.factory_lsb,
            a.ratio,
            if a.pass { "pass" } else { "FAIL" }
        );
    }
}

/// The driver's error by name (the log takes typed primitives only).
fn error_name<E>(e: &msreg_icm42688::Error<E>) -> &'static str {
    match e {
        msreg_icm42688::Error::Spi(_) => "SPI bus error",
        msreg_icm42688::Error::WrongDevice { .. } => "wrong WHO_AM_I",
        msreg_icm42688::Error::ResetNotDone { .. } => "soft reset not done",
        msreg_icm42688::Error::InvalidConfig => "invalid configuration",
        msreg_icm42688::Error::NotInitialized => "not initialised",
        msreg_icm42688::Error::SelfTestNoData => "no valid data",
    }
}

/// WHO_AM_I, reset, configuration, self-test (which re-applies the configuration).
fn bring_up(imu: &mut Imu, delay: &mut impl embedded_hal::delay::DelayNs) -> bool {
    if let Err(e) = imu.init(delay, Config::default()) {
        if let msreg_icm42688::Error::WrongDevice { found } = e {
            defmt::error!(
                "imu: WHO_AM_I {=u8:#x}, expected 0x47: no ICM-42688-P",
                found
            );
        } else {
            defmt::error!("imu: initialisation failed: {=str}", error_name(&e));
        }
        return false;
    }
    match imu.self_test(delay) {
        Ok(r) => {
            log_self_test(&r);
            defmt::info!(
                "imu self-test: {=str}",
                if r.passed() { "PASS" } else { "FAIL" }
            );
        }
        Err(e) => defmt::error!("imu self-test: {=str}", error_name(&e)),
    }
    defmt::info!("imu: 500 Hz, +-1000 deg/s, +-8 g, FIFO packet 3, INT1 data-ready on PC7");
    true
}

/// Reads the FIFO after a new pulse and feeds the samples.
fn pump_imu(imu: &mut Imu, stats: &mut ImuStats, session: &mut Session, vcp: &mut Vcp) {
    let pulse = imu::data_ready().count;
    if pulse == stats.last_pulse {
        return;
    }
    stats.last_pulse = pulse;
    let mut out = [Sample {
        stamp_ns: 0,
        accel: [0.0; 3],
        gyro: [0.0; 3],
        temperature_c: 0.0,
        device_timestamp: 0,
    }; msreg_icm42688::BURST_PACKETS];
    let read = match imu.read_fifo(imu::data_ready, &mut out) {
        Ok(r) => r,
        Err(_) => {
            stats.errors += 1;
            return;
        }
    };
    stats.bursts += 1;
    stats.invalid += read.invalid;
    stats.corrupt += u32::from(read.corrupt_header.is_some());
    stats.bad_count += u32::from(read.bad_count.is_some());
    for s in out.iter().take(read.samples) {
        stats.samples += 1;
        stats.fed += u32::from(feed::feed(session, vcp, s));
    }
    if read.fifo_packets as usize > read.samples + read.invalid as usize {
        // More than one burst's worth: read the rest on the next pass.
        stats.last_pulse = pulse.wrapping_sub(1);
    }
    log_imu(imu, stats, out.get(read.samples.wrapping_sub(1)));
}

fn log_imu(imu: &Imu, stats: &mut ImuStats, last: Option<&Sample>) {
    let now = clock::now_ns();
    if now < stats.last_log_ns.saturating_add(IMU_LOG_PERIOD_NS) {
        return;
    }
    stats.last_log_ns = now;
    let (a, g) = last.map_or(([0.0; 3], [0.0; 3]), |s| (s.accel, s.gyro));
    defmt::info!(
        "imu t {=u64} ms: {=u32} samples in {=u32} bursts ({=u32} fed), invalid {=u32}, corrupt {=u32}, bad count {=u32}, bus errors {=u32}, period {=f32} us, resyncs {=u32}; accel {=f32} {=f32} {=f32} m/s^2, gyro {=f32} {=f32} {=f32} rad/s",
        now / 1_000_000,
        stats.samples,
        stats.bursts,
        stats.fed,
        stats.invalid,
        stats.corrupt,
        stats.bad_count,
        stats.errors,
        imu.stamper().period_ns() / 1000.0,
        imu.stamper().resyncs(),
        a[0],
        a[1],
        a[2],
        g[0],
        g[1],
        g[2]
    );
}

/// Applies every received byte to the session (as the QEMU `link` binary's loop).
fn pump_link(session: &mut Session, deframer: &mut Deframer<HOST_FRAME_MAX>, vcp: &mut Vcp) {
    let dropped = vcp.take_dropped();
    session.overrun(vcp, dropped);
    while let Some(byte) = vcp.try_read_byte() {
        match deframer.push(byte) {
            Pushed::Pending => {}
            Pushed::Oversize => session.frame_error(vcp, msreg_protocol::FrameError::Oversize),
            Pushed::Frame(f) => match frame::decode::<HostMsg>(f) {
                // Received when its first byte arrived (stamped by the USART2 handler);
                // the session's clock is the device clock of the IMU stamps.
                Ok(packet) => {
                    let rx_ns = vcp.frame_start_ns().unwrap_or_else(clock::now_ns);
                    session.handle(vcp, packet, rx_ns, clock::now_ns);
                }
                Err(e) => session.frame_error(vcp, e),
            },
        }
    }
}

/// Everything the loop drives.
struct Board {
    vcp: Vcp,
    imu: Option<Imu>,
}

/// Clocks, device clock, SysTick, the link's UART, the IMU.
fn setup(dp: pac::Peripherals, mut cp: cortex_m::Peripherals) -> Option<Board> {
    let mut rcc = dp.RCC.freeze(
        RccConfig::hsi()
            .sysclk(180.MHz())
            .pclk1(45.MHz())
            .pclk2(90.MHz()),
    );
    let dwt = cp.DWT.constrain(cp.DCB, &rcc.clocks);
    let mut delay = dwt.delay();
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00FF_FFFF);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    let serial_config = SerialConfig::default().baudrate(vcp::BAUD.bps());
    let serial: Serial<pac::USART2> =
        Serial::new(dp.USART2, (gpioa.pa2, gpioa.pa3), serial_config, &mut rcc).ok()?;
    let (tx, rx) = serial.split();
    let vcp = Vcp::new(tx, rx);
    let mode = Mode {
        polarity: Polarity::IdleHigh,
        phase: Phase::CaptureOnSecondTransition,
    };
    let pins = (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7));
    let spi = Spi::new(dp.SPI1, pins, mode, imu::SPI_HZ.Hz(), &mut rcc);
    let cs = gpiob.pb6.into_push_pull_output();
    let mut imu = ExclusiveDevice::new_no_delay(spi, cs)
        .ok()
        .map(Icm42688::new)?;
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let mut exti = dp.EXTI;
    let mut int1 = gpioc.pc7.into_pull_down_input();
    int1.make_interrupt_source(&mut syscfg);
    int1.trigger_on_edge(&mut exti, Edge::Rising);
    int1.enable_interrupt(&mut exti);
    let imu = bring_up(&mut imu, &mut delay).then_some(imu);
    if imu.is_some() {
        imu::listen(int1);
    }
    Some(Board { vcp, imu })
}

#[entry]
fn main() -> ! {
    let (Some(dp), Some(cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let Some(mut board) = setup(dp, cp) else {
        defmt::error!("board setup failed");
        loop {
            cortex_m::asm::wfi();
        }
    };
    // SAFETY: `main` runs once and is the only user of both statics (no interrupt handler
    // touches them), so these are the only references ever made.
    let (session, deframer) =
        unsafe { (&mut *addr_of_mut!(SESSION), &mut *addr_of_mut!(DEFRAMER)) };
    defmt::info!(
        "msreg NUCLEO-F446RE ready: protocol v{=u16}, USART2 {=u32} baud, rx ring {=u32} B, IMU {=str}",
        msreg_protocol::VERSION,
        vcp::BAUD,
        vcp::RX_RING as u32,
        if board.imu.is_some() { "ICM-42688-P" } else { "absent" }
    );
    session.announce(&mut board.vcp);
    let mut stats = ImuStats::default();
    loop {
        pump_link(session, deframer, &mut board.vcp);
        if let Some(imu) = board.imu.as_mut() {
            pump_imu(imu, &mut stats, session, &mut board.vcp);
        }
        cortex_m::interrupt::free(|_| {
            let pulse_waiting = board.imu.is_some() && imu::data_ready().count != stats.last_pulse;
            if !board.vcp.has_input() && !pulse_waiting {
                // WFI wakes on a pending interrupt even with PRIMASK set.
                cortex_m::asm::wfi();
            }
        });
    }
}
