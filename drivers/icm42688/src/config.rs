//! Sensor configuration: output data rate, full-scale ranges, UI and anti-alias filters,
//! and the scale factors to SI units that follow from the ranges.

/// Standard gravity, m/s^2 (the datasheet's sensitivity is in LSB/g).
pub const STANDARD_GRAVITY: f32 = 9.806_65;
/// Degrees to radians.
const DEG: f32 = core::f32::consts::PI / 180.0;

/// Gyro full-scale range (`GYRO_CONFIG0.GYRO_FS_SEL`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GyroRange {
    /// +-2000 deg/s (`GYRO_FS_SEL` = 0).
    Dps2000,
    /// +-1000 deg/s (1).
    Dps1000,
    /// +-500 deg/s (2).
    Dps500,
    /// +-250 deg/s (3).
    Dps250,
    /// +-125 deg/s (4).
    Dps125,
    /// +-62.5 deg/s (5).
    Dps62_5,
    /// +-31.25 deg/s (6).
    Dps31_25,
    /// +-15.625 deg/s (7).
    Dps15_625,
}

impl GyroRange {
    /// Every range, in `GYRO_FS_SEL` order.
    pub const ALL: [GyroRange; 8] = [
        GyroRange::Dps2000,
        GyroRange::Dps1000,
        GyroRange::Dps500,
        GyroRange::Dps250,
        GyroRange::Dps125,
        GyroRange::Dps62_5,
        GyroRange::Dps31_25,
        GyroRange::Dps15_625,
    ];

    /// `GYRO_FS_SEL`.
    pub fn fs_sel(self) -> u8 {
        self as u8
    }

    /// Full scale, deg/s: 2000 / 2^FS_SEL.
    pub fn full_scale_dps(self) -> f32 {
        2000.0 / f32::from(1u8 << self.fs_sel())
    }

    /// rad/s per LSB: full scale / 32768 (the datasheet's 16.4 LSB/(deg/s) at +-2000 is
    /// 32768 / 2000 rounded).
    pub fn rad_per_s_per_lsb(self) -> f32 {
        self.full_scale_dps() * DEG / 32768.0
    }
}

/// Accelerometer full-scale range (`ACCEL_CONFIG0.ACCEL_FS_SEL`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccelRange {
    /// +-16 g (`ACCEL_FS_SEL` = 0).
    G16,
    /// +-8 g (1).
    G8,
    /// +-4 g (2).
    G4,
    /// +-2 g (3).
    G2,
}

impl AccelRange {
    /// Every range, in `ACCEL_FS_SEL` order.
    pub const ALL: [AccelRange; 4] = [
        AccelRange::G16,
        AccelRange::G8,
        AccelRange::G4,
        AccelRange::G2,
    ];

    /// `ACCEL_FS_SEL`.
    pub fn fs_sel(self) -> u8 {
        self as u8
    }

    /// Full scale, g: 16 / 2^FS_SEL.
    pub fn full_scale_g(self) -> f32 {
        16.0 / f32::from(1u8 << self.fs_sel())
    }

    /// m/s^2 per LSB: full scale / 32768 (2048 LSB/g at +-16 g).
    pub fn m_per_s2_per_lsb(self) -> f32 {
        self.full_scale_g() * STANDARD_GRAVITY / 32768.0
    }
}

/// Output data rate of both sensors in low-noise mode (`GYRO_ODR` / `ACCEL_ODR` codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Odr {
    /// 8 kHz (code 3).
    Hz8000,
    /// 4 kHz (4).
    Hz4000,
    /// 2 kHz (5).
    Hz2000,
    /// 1 kHz (6, the reset value).
    Hz1000,
    /// 500 Hz (15).
    Hz500,
    /// 200 Hz (7).
    Hz200,
    /// 100 Hz (8).
    Hz100,
    /// 50 Hz (9).
    Hz50,
    /// 25 Hz (10).
    Hz25,
}

impl Odr {
    /// The `GYRO_ODR` / `ACCEL_ODR` code.
    pub fn code(self) -> u8 {
        match self {
            Odr::Hz8000 => 3,
            Odr::Hz4000 => 4,
            Odr::Hz2000 => 5,
            Odr::Hz1000 => 6,
            Odr::Hz500 => 15,
            Odr::Hz200 => 7,
            Odr::Hz100 => 8,
            Odr::Hz50 => 9,
            Odr::Hz25 => 10,
        }
    }

    /// Nominal rate, Hz.
    pub fn hz(self) -> u32 {
        match self {
            Odr::Hz8000 => 8000,
            Odr::Hz4000 => 4000,
            Odr::Hz2000 => 2000,
            Odr::Hz1000 => 1000,
            Odr::Hz500 => 500,
            Odr::Hz200 => 200,
            Odr::Hz100 => 100,
            Odr::Hz50 => 50,
            Odr::Hz25 => 25,
        }
    }

    /// Nominal sample period, ns.
    pub fn period_ns(self) -> u32 {
        1_000_000_000 / self.hz()
    }
}

/// UI filter bandwidth (`GYRO_UI_FILT_BW` / `ACCEL_UI_FILT_BW`, low-noise mode): the
/// -3 dB bandwidth as a fraction of the ODR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UiFilter {
    /// ODR / 2 (code 0).
    OdrDiv2,
    /// max(400 Hz, ODR) / 4 (code 1, the reset value).
    OdrDiv4,
    /// max(400 Hz, ODR) / 5 (2).
    OdrDiv5,
    /// max(400 Hz, ODR) / 8 (3).
    OdrDiv8,
    /// max(400 Hz, ODR) / 10 (4).
    OdrDiv10,
    /// max(400 Hz, ODR) / 20 (6).
    OdrDiv20,
    /// max(400 Hz, ODR) / 40 (7).
    OdrDiv40,
}

impl UiFilter {
    /// The 4-bit code.
    pub fn code(self) -> u8 {
        match self {
            UiFilter::OdrDiv2 => 0,
            UiFilter::OdrDiv4 => 1,
            UiFilter::OdrDiv5 => 2,
            UiFilter::OdrDiv8 => 3,
            UiFilter::OdrDiv10 => 4,
            UiFilter::OdrDiv20 => 6,
            UiFilter::OdrDiv40 => 7,
        }
    }
}

/// Anti-alias filter (bank 1 `GYRO_AAF_*`, bank 2 `ACCEL_AAF_*`): `DELT`, `DELTSQR`
/// (= DELT^2 in the datasheet's table) and `BITSHIFT` for a 3 dB bandwidth. `None` in
/// [`Config::anti_alias`] keeps the reset setting.
///
/// The presets are from memory of the datasheet's table (section 5.3); check them against
/// your revision.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AntiAlias {
    /// `AAF_DELT` (6 bits).
    pub delt: u8,
    /// `AAF_DELTSQR` (12 bits).
    pub deltsqr: u16,
    /// `AAF_BITSHIFT` (4 bits).
    pub bitshift: u8,
}

impl AntiAlias {
    /// 213 Hz: for ODR 500 Hz (Nyquist 250 Hz).
    pub const HZ_213: AntiAlias = AntiAlias {
        delt: 5,
        deltsqr: 25,
        bitshift: 10,
    };
    /// 258 Hz.
    pub const HZ_258: AntiAlias = AntiAlias {
        delt: 6,
        deltsqr: 36,
        bitshift: 10,
    };
    /// 536 Hz: for ODR 1 kHz.
    pub const HZ_536: AntiAlias = AntiAlias {
        delt: 12,
        deltsqr: 144,
        bitshift: 8,
    };
    /// 997 Hz: for ODR 2 kHz.
    pub const HZ_997: AntiAlias = AntiAlias {
        delt: 21,
        deltsqr: 440,
        bitshift: 6,
    };

    /// True when every field fits its register bits.
    pub fn is_valid(&self) -> bool {
        self.delt < 64 && self.deltsqr < 4096 && self.bitshift < 16
    }
}

/// Everything [`crate::Icm42688::init`] writes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Output data rate of both sensors (the FIFO gets one packet per period).
    pub odr: Odr,
    /// Gyro full scale.
    pub gyro_range: GyroRange,
    /// Accelerometer full scale.
    pub accel_range: AccelRange,
    /// UI filter of the gyro.
    pub gyro_filter: UiFilter,
    /// UI filter of the accelerometer.
    pub accel_filter: UiFilter,
    /// Anti-alias filter of both sensors; `None` keeps the reset setting.
    pub anti_alias: Option<AntiAlias>,
}

impl Default for Config {
    /// 500 Hz, +-1000 deg/s, +-8 g, UI filters at ODR/4, anti-alias at 213 Hz: a vehicle IMU
    /// feeding the estimator (docs/firmware.md).
    fn default() -> Self {
        Self {
            odr: Odr::Hz500,
            gyro_range: GyroRange::Dps1000,
            accel_range: AccelRange::G8,
            gyro_filter: UiFilter::OdrDiv4,
            accel_filter: UiFilter::OdrDiv4,
            anti_alias: Some(AntiAlias::HZ_213),
        }
    }
}

impl Config {
    /// `GYRO_CONFIG0`.
    pub fn gyro_config0(&self) -> u8 {
        (self.gyro_range.fs_sel() << 5) | self.odr.code()
    }

    /// `ACCEL_CONFIG0`.
    pub fn accel_config0(&self) -> u8 {
        (self.accel_range.fs_sel() << 5) | self.odr.code()
    }

    /// `GYRO_ACCEL_CONFIG0`.
    pub fn gyro_accel_config0(&self) -> u8 {
        (self.accel_filter.code() << 4) | self.gyro_filter.code()
    }
}
