//! The self-test (datasheet section 10, "Self-test"; the procedure of TDK's reference
//! driver): the response of each axis to its built-in electrostatic actuation,
//! `mean(self-test on) - mean(self-test off)`, is compared with the factory response coded
//! in OTP (`XG_ST_DATA`.. in bank 1, `XA_ST_DATA`.. in bank 2).
//!
//! - Setup: gyro +-250 deg/s, accelerometer +-2 g (`FS_SEL` = 3 for both: the OTP codes
//!   are for that range), ODR 1 kHz, UI filters at ODR/10, sensors on in low-noise mode,
//!   [`SETTLE_MS`] to settle.
//! - [`SAMPLES`] samples 1 ms apart from the data registers with self-test off; the same
//!   with the gyro actuated (`EN_GX_ST | EN_GY_ST | EN_GZ_ST`), then with the accelerometer
//!   actuated (`ACCEL_ST_POWER | EN_AX_ST | EN_AY_ST | EN_AZ_ST`), [`SETTLE_MS`] after each
//!   switch.
//! - Factory response of a code `c` at `FS_SEL` = 3: `2620 * 1.01^(c - 1)` LSB.
//! - Pass: `0.5 <= |response| / factory <= 1.5` on every axis (the datasheet's self-test
//!   response "relative to factory trim", -50 % to +50 %).
//!
//! A code of 0 means the factory stored no response: the datasheet then has an absolute
//! criterion instead, whose thresholds we do not know reliably, so such an axis fails with
//! `factory_lsb = 0`, to be checked by hand. The setup is this driver's reading of the
//! datasheet and TDK's reference driver, written from memory: see [`crate::regs`].
//!
//! The test leaves the part reconfigured with the configuration of the last
//! [`crate::Icm42688::init`] (FIFO flushed, time stamps restarted), if there was one.

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;

use crate::regs::{self, bank0, bank1, bank2};
use crate::{Error, Icm42688};

/// Samples averaged per state.
pub const SAMPLES: usize = 200;
/// Wait after turning the sensors on and after each self-test switch, ms.
pub const SETTLE_MS: u32 = 200;
/// `GYRO_CONFIG0` / `ACCEL_CONFIG0` during the test: `FS_SEL` = 3, ODR 1 kHz.
pub const ST_SENSOR_CONFIG: u8 = (3 << 5) | 6;
/// `GYRO_ACCEL_CONFIG0` during the test: both UI filters at ODR/10.
pub const ST_FILTER_CONFIG: u8 = 0x44;
/// Pass band of `|response| / factory`.
pub const RATIO_MIN: f32 = 0.5;
/// Pass band of `|response| / factory`.
pub const RATIO_MAX: f32 = 1.5;

/// One axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisResult {
    /// OTP code.
    pub code: u8,
    /// Measured response, LSB at `FS_SEL` = 3.
    pub response_lsb: f32,
    /// Factory response from the code, LSB (0: none stored).
    pub factory_lsb: f32,
    /// `|response| / factory` (0 when no factory response).
    pub ratio: f32,
    /// Inside [`RATIO_MIN`], [`RATIO_MAX`].
    pub pass: bool,
}

impl AxisResult {
    /// Judges a measured response against an OTP code.
    pub fn judge(code: u8, response_lsb: f32) -> Self {
        let factory_lsb = factory_response(code);
        let ratio = if factory_lsb > 0.0 {
            response_lsb.abs() / factory_lsb
        } else {
            0.0
        };
        Self {
            code,
            response_lsb,
            factory_lsb,
            ratio,
            pass: factory_lsb > 0.0 && (RATIO_MIN..=RATIO_MAX).contains(&ratio),
        }
    }
}

/// Gyro X, Y, Z and accelerometer X, Y, Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelfTestReport {
    /// Gyro axes.
    pub gyro: [AxisResult; 3],
    /// Accelerometer axes.
    pub accel: [AxisResult; 3],
}

impl SelfTestReport {
    /// Every axis passed.
    pub fn passed(&self) -> bool {
        self.gyro.iter().chain(&self.accel).all(|a| a.pass)
    }
}

/// Factory self-test response at `FS_SEL` = 3 for an OTP code: `2620 * 1.01^(code - 1)`
/// LSB; 0 for code 0.
pub fn factory_response(code: u8) -> f32 {
    if code == 0 {
        return 0.0;
    }
    (1..code).fold(2620.0f32, |v, _| v * 1.01)
}

/// Factory self-test codes: gyro X/Y/Z, accel X/Y/Z.
type OtpCodes = ([u8; 3], [u8; 3]);

/// Mean accel and gyro outputs, LSB.
#[derive(Clone, Copy, Debug, Default)]
struct Means {
    accel: [f32; 3],
    gyro: [f32; 3],
}

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// Runs the self-test (module docs) and reconfigures the part. `Err` only for the bus or
    /// a sensor that produced no valid data; a failed axis is in the report.
    pub fn self_test(
        &mut self,
        delay: &mut impl DelayNs,
    ) -> Result<SelfTestReport, Error<SPI::Error>> {
        self.select_bank(0)?;
        self.write_register(bank0::GYRO_CONFIG0, ST_SENSOR_CONFIG)?;
        self.write_register(bank0::ACCEL_CONFIG0, ST_SENSOR_CONFIG)?;
        self.write_register(bank0::GYRO_ACCEL_CONFIG0, ST_FILTER_CONFIG)?;
        self.write_register(bank0::PWR_MGMT0, regs::PWR_LOW_NOISE)?;
        delay.delay_ms(SETTLE_MS);
        let off = self.mean_outputs(delay)?;
        let gyro_on = self.actuated(delay, regs::GYRO_ST_EN)?;
        let accel_on = self.actuated(delay, regs::ACCEL_ST_EN)?;
        let (gyro_codes, accel_codes) = self.self_test_codes()?;
        let axis = |codes: [u8; 3], on: [f32; 3], off: [f32; 3], i: usize| {
            AxisResult::judge(codes[i], on[i] - off[i])
        };
        let report = SelfTestReport {
            gyro: [0, 1, 2].map(|i| axis(gyro_codes, gyro_on.gyro, off.gyro, i)),
            accel: [0, 1, 2].map(|i| axis(accel_codes, accel_on.accel, off.accel, i)),
        };
        if let Some(config) = self.config {
            self.configure(delay, config)?;
        }
        Ok(report)
    }

    /// Mean outputs with `SELF_TEST_CONFIG` = `enable`; self-test off again afterwards.
    fn actuated(
        &mut self,
        delay: &mut impl DelayNs,
        enable: u8,
    ) -> Result<Means, Error<SPI::Error>> {
        self.write_register(bank0::SELF_TEST_CONFIG, enable)?;
        delay.delay_ms(SETTLE_MS);
        let means = self.mean_outputs(delay);
        self.write_register(bank0::SELF_TEST_CONFIG, 0)?;
        delay.delay_ms(SETTLE_MS);
        means
    }

    /// Mean of [`SAMPLES`] reads of the 12 data registers, 1 ms apart; samples with the
    /// invalid marker are left out; fewer than half valid is [`Error::SelfTestNoData`].
    fn mean_outputs(&mut self, delay: &mut impl DelayNs) -> Result<Means, Error<SPI::Error>> {
        let mut sum = [0i64; 6];
        let mut valid = 0usize;
        for _ in 0..SAMPLES {
            delay.delay_ms(1);
            let mut b = [0u8; 12];
            self.read_registers(bank0::ACCEL_DATA_X1, &mut b)?;
            let v: [i16; 6] =
                core::array::from_fn(|i| i16::from_be_bytes([b[2 * i], b[2 * i + 1]]));
            if v.contains(&crate::fifo::INVALID_SAMPLE) {
                continue;
            }
            for (s, x) in sum.iter_mut().zip(v) {
                *s += i64::from(x);
            }
            valid += 1;
        }
        if valid * 2 < SAMPLES {
            return Err(Error::SelfTestNoData);
        }
        let mean = |i: usize| sum[i] as f32 / valid as f32;
        Ok(Means {
            accel: [mean(0), mean(1), mean(2)],
            gyro: [mean(3), mean(4), mean(5)],
        })
    }

    /// OTP codes: gyro X/Y/Z (bank 1), accel X/Y/Z (bank 2); back to bank 0.
    fn self_test_codes(&mut self) -> Result<OtpCodes, Error<SPI::Error>> {
        let (mut g, mut a) = ([0u8; 3], [0u8; 3]);
        self.select_bank(1)?;
        self.read_registers(bank1::XG_ST_DATA, &mut g)?;
        self.select_bank(2)?;
        self.read_registers(bank2::XA_ST_DATA, &mut a)?;
        self.select_bank(0)?;
        Ok((g, a))
    }
}
