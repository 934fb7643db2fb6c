//! Register map of the ICM-42688-P (TDK InvenSense datasheet DS-000347, section 13-16), with
//! the datasheet's names. Only the registers and fields the driver uses are listed.
//!
//! Confidence: the addresses and fields below are written from memory of the datasheet and
//! cross-checked against each other (bank layout, reset values, the well-known FIFO packet
//! 3 header 0x68); they were not compared with a copy of the datasheet in this repository
//! (there is none). The ones used by most open drivers (bank select, WHO_AM_I, power,
//! sensor configuration, FIFO, interrupt routing, self-test enable and the self-test OTP
//! codes) are the most certain; the anti-alias filter presets ([`crate::AntiAlias`]) and
//! `INT_CONFIG1` are the least. Check them against the datasheet revision of the parts
//! you fit before flying.
//!
//! SPI: an access is one chip-select cycle: the first byte is the register address, bit 7
//! set for a read ([`READ`]); a burst continues at the next address, except `FIFO_DATA`,
//! which streams the FIFO.

/// Bit 7 of the address byte: read.
pub const READ: u8 = 0x80;

/// `REG_BANK_SEL` (all banks, 0x76): bits 2:0 `BANK_SEL`.
pub const REG_BANK_SEL: u8 = 0x76;

/// User bank 0.
pub mod bank0 {
    /// `DEVICE_CONFIG`: bit 0 `SOFT_RESET_CONFIG` (1 = reset; wait 1 ms), bit 4 `SPI_MODE`.
    pub const DEVICE_CONFIG: u8 = 0x11;
    /// `INT_CONFIG`: bit 2 `INT1_MODE` (0 pulsed, 1 latched), bit 1 `INT1_DRIVE_CIRCUIT`
    /// (1 push-pull), bit 0 `INT1_POLARITY` (1 active high).
    pub const INT_CONFIG: u8 = 0x14;
    /// `FIFO_CONFIG`: bits 7:6 `FIFO_MODE` (00 bypass, 01 stream-to-FIFO, 1x stop-on-full).
    pub const FIFO_CONFIG: u8 = 0x16;
    /// `TEMP_DATA1` (0x1D, 0x1E): temperature, 16 bit big-endian; then `ACCEL_DATA_X1`
    /// (0x1F) .. `GYRO_DATA_Z0` (0x2A): accel X, Y, Z and gyro X, Y, Z, 16 bit big-endian.
    pub const TEMP_DATA1: u8 = 0x1D;
    /// `ACCEL_DATA_X1`: first of the 12 sensor data bytes (accel XYZ, gyro XYZ).
    pub const ACCEL_DATA_X1: u8 = 0x1F;
    /// `INT_STATUS`: bit 4 `RESET_DONE_INT`, bit 3 `DATA_RDY_INT`, bit 2 `FIFO_THS_INT`,
    /// bit 1 `FIFO_FULL_INT` (cleared on read).
    pub const INT_STATUS: u8 = 0x2D;
    /// `FIFO_COUNTH` (0x2E), `FIFO_COUNTL` (0x2F): bytes in the FIFO, big-endian (reset
    /// value of `INTF_CONFIG0`: `FIFO_COUNT_REC` = 0 counts bytes, `FIFO_COUNT_ENDIAN` = 1).
    /// Reading `FIFO_COUNTH` latches `FIFO_COUNTL`: read both in one burst.
    pub const FIFO_COUNTH: u8 = 0x2E;
    /// `FIFO_DATA`: FIFO read port.
    pub const FIFO_DATA: u8 = 0x30;
    /// `SIGNAL_PATH_RESET`: bit 1 `FIFO_FLUSH`.
    pub const SIGNAL_PATH_RESET: u8 = 0x4B;
    /// `PWR_MGMT0`: bit 5 `TEMP_DIS`, bits 3:2 `GYRO_MODE` (11 low noise), bits 1:0
    /// `ACCEL_MODE` (11 low noise). No register write for 200 us after turning a sensor on.
    pub const PWR_MGMT0: u8 = 0x4E;
    /// `GYRO_CONFIG0`: bits 7:5 `GYRO_FS_SEL`, bits 3:0 `GYRO_ODR`.
    pub const GYRO_CONFIG0: u8 = 0x4F;
    /// `ACCEL_CONFIG0`: bits 7:5 `ACCEL_FS_SEL`, bits 3:0 `ACCEL_ODR`.
    pub const ACCEL_CONFIG0: u8 = 0x50;
    /// `GYRO_ACCEL_CONFIG0`: bits 7:4 `ACCEL_UI_FILT_BW`, bits 3:0 `GYRO_UI_FILT_BW`.
    pub const GYRO_ACCEL_CONFIG0: u8 = 0x52;
    /// `FIFO_CONFIG1`: bit 4 `FIFO_HIRES_EN`, bit 2 `FIFO_TEMP_EN`, bit 1 `FIFO_GYRO_EN`,
    /// bit 0 `FIFO_ACCEL_EN`.
    pub const FIFO_CONFIG1: u8 = 0x5F;
    /// `INT_CONFIG1`: bit 6 `INT_TPULSE_DURATION` (0: 100 us), bit 4 `INT_ASYNC_RESET`
    /// (reset value 1; the datasheet asks for 0 for proper INT1/INT2 operation).
    pub const INT_CONFIG1: u8 = 0x64;
    /// `INT_SOURCE0`: bit 4 `RESET_DONE_INT1_EN` (reset value), bit 3 `UI_DRDY_INT1_EN`,
    /// bit 2 `FIFO_THS_INT1_EN`, bit 1 `FIFO_FULL_INT1_EN`.
    pub const INT_SOURCE0: u8 = 0x65;
    /// `SELF_TEST_CONFIG`: bit 6 `ACCEL_ST_POWER`, bits 5:3 `EN_AZ_ST`, `EN_AY_ST`,
    /// `EN_AX_ST`, bits 2:0 `EN_GZ_ST`, `EN_GY_ST`, `EN_GX_ST`.
    pub const SELF_TEST_CONFIG: u8 = 0x70;
    /// `WHO_AM_I`: reads [`super::WHO_AM_I_VALUE`].
    pub const WHO_AM_I: u8 = 0x75;
}

/// User bank 1.
pub mod bank1 {
    /// `GYRO_CONFIG_STATIC3`: bits 5:0 `GYRO_AAF_DELT`.
    pub const GYRO_CONFIG_STATIC3: u8 = 0x0C;
    /// `GYRO_CONFIG_STATIC4`: `GYRO_AAF_DELTSQR[7:0]`.
    pub const GYRO_CONFIG_STATIC4: u8 = 0x0D;
    /// `GYRO_CONFIG_STATIC5`: bits 7:4 `GYRO_AAF_BITSHIFT`, bits 3:0 `GYRO_AAF_DELTSQR[11:8]`.
    pub const GYRO_CONFIG_STATIC5: u8 = 0x0E;
    /// `XG_ST_DATA` (0x5F), `YG_ST_DATA` (0x60), `ZG_ST_DATA` (0x61): factory gyro
    /// self-test codes (OTP).
    pub const XG_ST_DATA: u8 = 0x5F;
}

/// User bank 2.
pub mod bank2 {
    /// `ACCEL_CONFIG_STATIC2`: bits 6:1 `ACCEL_AAF_DELT`, bit 0 `ACCEL_AAF_DIS`.
    pub const ACCEL_CONFIG_STATIC2: u8 = 0x03;
    /// `ACCEL_CONFIG_STATIC3`: `ACCEL_AAF_DELTSQR[7:0]`.
    pub const ACCEL_CONFIG_STATIC3: u8 = 0x04;
    /// `ACCEL_CONFIG_STATIC4`: bits 7:4 `ACCEL_AAF_BITSHIFT`, bits 3:0
    /// `ACCEL_AAF_DELTSQR[11:8]`.
    pub const ACCEL_CONFIG_STATIC4: u8 = 0x05;
    /// `XA_ST_DATA` (0x3B), `YA_ST_DATA` (0x3C), `ZA_ST_DATA` (0x3D): factory accel
    /// self-test codes (OTP).
    pub const XA_ST_DATA: u8 = 0x3B;
}

/// `WHO_AM_I` of the ICM-42688-P.
pub const WHO_AM_I_VALUE: u8 = 0x47;

/// `DEVICE_CONFIG.SOFT_RESET_CONFIG`.
pub const SOFT_RESET: u8 = 0x01;
/// `INT_STATUS.RESET_DONE_INT`.
pub const RESET_DONE: u8 = 1 << 4;
/// `SIGNAL_PATH_RESET.FIFO_FLUSH`.
pub const FIFO_FLUSH: u8 = 1 << 1;
/// `FIFO_CONFIG.FIFO_MODE` = stream-to-FIFO.
pub const FIFO_MODE_STREAM: u8 = 0b01 << 6;
/// `FIFO_CONFIG1`: accel, gyro and temperature in the FIFO (packet 3, 16 bytes).
pub const FIFO_PACKET3: u8 = 0b0000_0111;
/// `PWR_MGMT0`: gyro and accel in low-noise mode, temperature sensor on.
pub const PWR_LOW_NOISE: u8 = 0b0000_1111;
/// `PWR_MGMT0`: everything off.
pub const PWR_OFF: u8 = 0x00;
/// `INT_CONFIG`: INT1 pulsed, push-pull, active high.
pub const INT1_PULSED_PUSH_PULL_HIGH: u8 = 0b0000_0011;
/// `INT_CONFIG1`: 100 us pulses, `INT_ASYNC_RESET` cleared.
pub const INT_CONFIG1_VALUE: u8 = 0x00;
/// `INT_SOURCE0.UI_DRDY_INT1_EN`.
pub const UI_DRDY_INT1_EN: u8 = 1 << 3;
/// `SELF_TEST_CONFIG`: `EN_GX_ST | EN_GY_ST | EN_GZ_ST`.
pub const GYRO_ST_EN: u8 = 0b0000_0111;
/// `SELF_TEST_CONFIG`: `ACCEL_ST_POWER | EN_AX_ST | EN_AY_ST | EN_AZ_ST`.
pub const ACCEL_ST_EN: u8 = 0b0111_1000;

/// FIFO packet header bits (datasheet section 6.1, "FIFO header").
pub mod header {
    /// `HEADER_MSG`: the FIFO is empty (the rest of the packet is not valid).
    pub const MSG: u8 = 1 << 7;
    /// `HEADER_ACCEL`: the packet holds accel data.
    pub const ACCEL: u8 = 1 << 6;
    /// `HEADER_GYRO`: the packet holds gyro data.
    pub const GYRO: u8 = 1 << 5;
    /// `HEADER_20`: 20-bit packet (packet 4, `FIFO_HIRES_EN`).
    pub const HIRES: u8 = 1 << 4;
    /// `HEADER_TIMESTAMP_FSYNC` (bits 3:2): 10 = ODR time stamp, 11 = FSYNC time stamp.
    pub const TIMESTAMP_MASK: u8 = 0b11 << 2;
    /// `HEADER_ODR_ACCEL` (bit 1) and `HEADER_ODR_GYRO` (bit 0): the ODR changed.
    pub const ODR_CHANGED: u8 = 0b11;
}
