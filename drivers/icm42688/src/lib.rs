//! Driver of the TDK InvenSense ICM-42688-P 6-axis IMU over an embedded-hal 1.0
//! [`SpiDevice`], `no_std` and allocation-free.
//!
//! - [`Icm42688::init`]: `WHO_AM_I` check (0x47), soft reset, output data rate, full-scale
//!   ranges, UI and anti-alias filters, INT1 as a pulsed data-ready interrupt, the FIFO in
//!   stream mode with packet 3 (accel + gyro + temperature + time stamp), sensors on in
//!   low-noise mode.
//! - [`Icm42688::read_fifo`]: reads `FIFO_COUNT`, then every whole packet in one burst of
//!   `FIFO_DATA`; parses and checks each header; scales to SI units (m/s^2, rad/s) with the
//!   configured ranges; stamps each sample on the caller's monotonic clock from the latest
//!   data-ready interrupt, the ODR and the FIFO depth ([`stamp`]). Packets holding the
//!   invalid marker are skipped and counted; a corrupt header flushes the FIFO.
//! - [`Icm42688::self_test`]: the datasheet's self-test (gyro and accelerometer responses
//!   against the factory OTP codes, pass at 50-150 %).
//!
//! Everything read from the bus is checked: a bad value is an [`Error`] or a counted field of
//! [`FifoRead`], never a panic. The register map is in [`regs`], with the datasheet's names
//! and a note on how sure each part of it is.
//!
//! With the `estimator` feature, [`estimator::imu_sample`] turns a [`Sample`] into the
//! estimator's `ImuSample<f32>`, the type the firmware's filter propagates with.
#![no_std]

pub mod config;
pub mod error;
#[cfg(feature = "estimator")]
pub mod estimator;
pub mod fifo;
pub mod regs;
pub mod selftest;
pub mod stamp;

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::{Operation, SpiDevice};

pub use config::{AccelRange, AntiAlias, Config, GyroRange, Odr, UiFilter};
pub use error::Error;
pub use fifo::{Packet, RawPacket, Sample};
pub use selftest::{AxisResult, SelfTestReport};
pub use stamp::{DataReady, Stamper};

use regs::{bank0, bank1, bank2};

/// Most packets read in one burst (the burst buffer is `16 x` this on the stack).
pub const BURST_PACKETS: usize = 32;

/// What one [`Icm42688::read_fifo`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FifoRead {
    /// Samples written to the front of the output slice.
    pub samples: usize,
    /// Packets skipped because a channel held the invalid marker (sensor settling).
    pub invalid: u32,
    /// Whole packets in the FIFO when it was read (more than read when the output or
    /// [`BURST_PACKETS`] was smaller: call again).
    pub fifo_packets: u32,
    /// The header of a corrupt packet (not packet 3): parsing stopped there and the FIFO
    /// was flushed; the samples before it are kept.
    pub corrupt_header: Option<u8>,
    /// `FIFO_COUNT` was larger than the FIFO (2048 bytes): nothing was read, the FIFO was
    /// flushed.
    pub bad_count: Option<u16>,
}

/// The driver. Owns the SPI device; [`Icm42688::release`] gives it back.
pub struct Icm42688<SPI> {
    spi: SPI,
    config: Option<Config>,
    stamper: Stamper,
}

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// A driver for the part on `spi` (mode 0 or 3, up to 24 MHz). Nothing is sent yet.
    pub fn new(spi: SPI) -> Self {
        Self {
            spi,
            config: None,
            stamper: Stamper::new(Odr::Hz1000.period_ns()),
        }
    }

    /// The SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }

    /// The configuration applied by [`Icm42688::init`], if any.
    pub fn config(&self) -> Option<&Config> {
        self.config.as_ref()
    }

    /// The time stamper (period estimate, resync and clamp counters).
    pub fn stamper(&self) -> &Stamper {
        &self.stamper
    }

    /// Reads `buf.len()` registers from `addr` of the selected bank in one burst.
    pub fn read_registers(&mut self, addr: u8, buf: &mut [u8]) -> Result<(), Error<SPI::Error>> {
        self.spi
            .transaction(&mut [Operation::Write(&[addr | regs::READ]), Operation::Read(buf)])?;
        Ok(())
    }

    /// Reads one register of the selected bank.
    pub fn read_register(&mut self, addr: u8) -> Result<u8, Error<SPI::Error>> {
        let mut b = [0u8];
        self.read_registers(addr, &mut b)?;
        Ok(b[0])
    }

    /// Writes one register of the selected bank.
    pub fn write_register(&mut self, addr: u8, value: u8) -> Result<(), Error<SPI::Error>> {
        self.spi.write(&[addr & !regs::READ, value])?;
        Ok(())
    }

    /// Selects a register bank (`REG_BANK_SEL`).
    pub fn select_bank(&mut self, bank: u8) -> Result<(), Error<SPI::Error>> {
        self.write_register(regs::REG_BANK_SEL, bank & 0b111)
    }

    /// `WHO_AM_I` (bank 0).
    pub fn who_am_i(&mut self) -> Result<u8, Error<SPI::Error>> {
        self.read_register(bank0::WHO_AM_I)
    }

    /// Bank 0, checks `WHO_AM_I`, soft reset, waits 1 ms and checks `RESET_DONE_INT`.
    pub fn reset(&mut self, delay: &mut impl DelayNs) -> Result<(), Error<SPI::Error>> {
        self.select_bank(0)?;
        let found = self.who_am_i()?;
        if found != regs::WHO_AM_I_VALUE {
            return Err(Error::WrongDevice { found });
        }
        self.write_register(bank0::DEVICE_CONFIG, regs::SOFT_RESET)?;
        delay.delay_ms(1);
        let int_status = self.read_register(bank0::INT_STATUS)?;
        if int_status & regs::RESET_DONE == 0 {
            return Err(Error::ResetNotDone { int_status });
        }
        self.config = None;
        Ok(())
    }

    /// [`Icm42688::reset`], then [`Icm42688::configure`].
    pub fn init(
        &mut self,
        delay: &mut impl DelayNs,
        config: Config,
    ) -> Result<(), Error<SPI::Error>> {
        if config.anti_alias.is_some_and(|a| !a.is_valid()) {
            return Err(Error::InvalidConfig);
        }
        self.reset(delay)?;
        self.configure(delay, config)
    }

    /// Writes the configuration (sensors off while it changes), the interrupt and FIFO
    /// setup, turns both sensors on in low-noise mode (then 200 us without a write, as the
    /// datasheet asks), flushes the FIFO and restarts the time stamps.
    pub fn configure(
        &mut self,
        delay: &mut impl DelayNs,
        config: Config,
    ) -> Result<(), Error<SPI::Error>> {
        if config.anti_alias.is_some_and(|a| !a.is_valid()) {
            return Err(Error::InvalidConfig);
        }
        self.write_register(bank0::PWR_MGMT0, regs::PWR_OFF)?;
        self.write_register(bank0::GYRO_CONFIG0, config.gyro_config0())?;
        self.write_register(bank0::ACCEL_CONFIG0, config.accel_config0())?;
        self.write_register(bank0::GYRO_ACCEL_CONFIG0, config.gyro_accel_config0())?;
        if let Some(aaf) = config.anti_alias {
            self.write_anti_alias(&aaf)?;
        }
        self.write_register(bank0::INT_CONFIG, regs::INT1_PULSED_PUSH_PULL_HIGH)?;
        self.write_register(bank0::INT_CONFIG1, regs::INT_CONFIG1_VALUE)?;
        self.write_register(bank0::INT_SOURCE0, regs::UI_DRDY_INT1_EN)?;
        self.write_register(bank0::FIFO_CONFIG, regs::FIFO_MODE_STREAM)?;
        self.write_register(bank0::FIFO_CONFIG1, regs::FIFO_PACKET3)?;
        self.write_register(bank0::PWR_MGMT0, regs::PWR_LOW_NOISE)?;
        delay.delay_us(200);
        self.write_register(bank0::SIGNAL_PATH_RESET, regs::FIFO_FLUSH)?;
        self.config = Some(config);
        self.stamper = Stamper::new(config.odr.period_ns());
        Ok(())
    }

    /// Gyro (bank 1) and accelerometer (bank 2) anti-alias filters; back to bank 0.
    fn write_anti_alias(&mut self, a: &AntiAlias) -> Result<(), Error<SPI::Error>> {
        let sq_low = (a.deltsqr & 0xFF) as u8;
        let shift_sq_high = (a.bitshift << 4) | ((a.deltsqr >> 8) as u8 & 0x0F);
        self.select_bank(1)?;
        self.write_register(bank1::GYRO_CONFIG_STATIC3, a.delt & 0x3F)?;
        self.write_register(bank1::GYRO_CONFIG_STATIC4, sq_low)?;
        self.write_register(bank1::GYRO_CONFIG_STATIC5, shift_sq_high)?;
        self.select_bank(2)?;
        // ACCEL_AAF_DIS (bit 0) stays 0: the filter is on.
        self.write_register(bank2::ACCEL_CONFIG_STATIC2, (a.delt & 0x3F) << 1)?;
        self.write_register(bank2::ACCEL_CONFIG_STATIC3, sq_low)?;
        self.write_register(bank2::ACCEL_CONFIG_STATIC4, shift_sq_high)?;
        self.select_bank(0)
    }

    /// Flushes the FIFO (`SIGNAL_PATH_RESET.FIFO_FLUSH`); the next burst re-anchors the
    /// time stamps.
    pub fn flush_fifo(&mut self) -> Result<(), Error<SPI::Error>> {
        self.write_register(bank0::SIGNAL_PATH_RESET, regs::FIFO_FLUSH)?;
        self.stamper.flush();
        Ok(())
    }

    /// Whole packets in the FIFO (`FIFO_COUNTH`/`FIFO_COUNTL`, bytes, big-endian), or
    /// `Err(count)` for a count beyond the FIFO's size.
    fn fifo_packets(&mut self) -> Result<Result<u32, u16>, Error<SPI::Error>> {
        let mut c = [0u8; 2];
        self.read_registers(bank0::FIFO_COUNTH, &mut c)?;
        let bytes = u16::from_be_bytes(c);
        if bytes > fifo::FIFO_BYTES {
            return Ok(Err(bytes));
        }
        Ok(Ok(u32::from(bytes) / fifo::PACKET_LEN as u32))
    }

    /// Reads the FIFO: up to `out.len()` (at most [`BURST_PACKETS`]) packets in one burst,
    /// scaled and stamped. `data_ready` returns a copy of the latest data-ready pulse; it is
    /// called before the FIFO count is read and after the burst ([`stamp`]). See
    /// [`FifoRead`] for what can go wrong with the data.
    pub fn read_fifo(
        &mut self,
        mut data_ready: impl FnMut() -> DataReady,
        out: &mut [Sample],
    ) -> Result<FifoRead, Error<SPI::Error>> {
        let config = self.config.ok_or(Error::NotInitialized)?;
        let before = data_ready();
        let fifo_packets = match self.fifo_packets()? {
            Ok(n) => n,
            Err(count) => {
                self.flush_fifo()?;
                return Ok(FifoRead {
                    bad_count: Some(count),
                    ..FifoRead::default()
                });
            }
        };
        let mut report = FifoRead {
            fifo_packets,
            ..FifoRead::default()
        };
        let n = (fifo_packets as usize).min(out.len()).min(BURST_PACKETS);
        if n == 0 {
            return Ok(report);
        }
        let mut buf = [0u8; BURST_PACKETS * fifo::PACKET_LEN];
        let bytes = &mut buf[..n * fifo::PACKET_LEN];
        self.read_registers(bank0::FIFO_DATA, bytes)?;
        let anchor = self.stamper.begin_burst(before, data_ready(), fifo_packets);
        for chunk in bytes.chunks_exact(fifo::PACKET_LEN) {
            let mut packet = [0u8; fifo::PACKET_LEN];
            packet.copy_from_slice(chunk);
            match fifo::parse(&packet) {
                Ok(Packet::Empty) => break,
                Ok(Packet::Invalid(_)) => {
                    self.stamper.next_stamp(before, anchor);
                    report.invalid += 1;
                }
                Ok(Packet::Data(p)) => {
                    let stamp = self.stamper.next_stamp(before, anchor);
                    if let Some(slot) = out.get_mut(report.samples) {
                        *slot = Sample::from_raw(&p, &config, stamp);
                        report.samples += 1;
                    }
                }
                Err(header) => {
                    report.corrupt_header = Some(header);
                    self.flush_fifo()?;
                    break;
                }
            }
        }
        Ok(report)
    }
}
