//! Expected SPI transactions, written from the datasheet's register map (addresses and
//! values are literals here, not the driver's constants, so a wrong constant fails a test).
#![allow(dead_code, reason = "each test file uses a part of the helpers")]

use embedded_hal_mock::eh1::spi::Transaction;

pub type T = Transaction<u8>;

/// A register write: one chip-select cycle, address with bit 7 clear, then the value.
pub fn w(reg: u8, value: u8) -> Vec<T> {
    assert!(reg < 0x80);
    vec![
        T::transaction_start(),
        T::write_vec(vec![reg, value]),
        T::transaction_end(),
    ]
}

/// A register read: one chip-select cycle, address with bit 7 set, then the bytes.
pub fn r(reg: u8, response: &[u8]) -> Vec<T> {
    assert!(reg < 0x80);
    vec![
        T::transaction_start(),
        T::write_vec(vec![reg | 0x80]),
        T::read_vec(response.to_vec()),
        T::transaction_end(),
    ]
}

/// Bank 0, WHO_AM_I (0x75) = 0x47, DEVICE_CONFIG (0x11) soft reset, INT_STATUS (0x2D) with
/// RESET_DONE_INT (bit 4).
pub fn reset_sequence() -> Vec<T> {
    [
        w(0x76, 0x00),
        r(0x75, &[0x47]),
        w(0x11, 0x01),
        r(0x2D, &[0x10]),
    ]
    .concat()
}

/// The datasheet's writes for a configuration: PWR_MGMT0 (0x4E) off, GYRO_CONFIG0 (0x4F),
/// ACCEL_CONFIG0 (0x50), GYRO_ACCEL_CONFIG0 (0x52), the anti-alias filter (`(delt,
/// deltsqr, bitshift)`, bank 1 0x0C-0x0E and bank 2 0x03-0x05), INT_CONFIG (0x14) INT1
/// pulsed push-pull active high, INT_CONFIG1 (0x64) INT_ASYNC_RESET cleared, INT_SOURCE0
/// (0x65) UI_DRDY_INT1_EN, FIFO_CONFIG (0x16) stream, FIFO_CONFIG1 (0x5F) accel + gyro +
/// temp, PWR_MGMT0 low noise, SIGNAL_PATH_RESET (0x4B) FIFO_FLUSH.
pub fn configure_sequence(
    gyro0: u8,
    accel0: u8,
    filters: u8,
    aaf: Option<(u8, u16, u8)>,
) -> Vec<T> {
    let mut t = [
        w(0x4E, 0x00),
        w(0x4F, gyro0),
        w(0x50, accel0),
        w(0x52, filters),
    ]
    .concat();
    if let Some((delt, sq, shift)) = aaf {
        let high = (shift << 4) | (sq >> 8) as u8;
        t.extend(
            [
                w(0x76, 1),
                w(0x0C, delt),
                w(0x0D, sq as u8),
                w(0x0E, high),
                w(0x76, 2),
                w(0x03, delt << 1),
                w(0x04, sq as u8),
                w(0x05, high),
                w(0x76, 0),
            ]
            .concat(),
        );
    }
    t.extend(
        [
            w(0x14, 0x03),
            w(0x64, 0x00),
            w(0x65, 0x08),
            w(0x16, 0x40),
            w(0x5F, 0x07),
            w(0x4E, 0x0F),
            w(0x4B, 0x02),
        ]
        .concat(),
    );
    t
}

/// `init` with `Config::default()`: 500 Hz (ODR code 15), +-1000 deg/s (FS_SEL 1), +-8 g
/// (FS_SEL 1), UI filters ODR/4 (code 1 each), anti-alias 213 Hz (5, 25, 10).
pub fn default_init_sequence() -> Vec<T> {
    [
        reset_sequence(),
        configure_sequence(0x2F, 0x2F, 0x11, Some((5, 25, 10))),
    ]
    .concat()
}

/// FIFO packet 3: header 0x68 (accel, gyro, ODR time stamp), big-endian words.
pub fn packet3(accel: [i16; 3], gyro: [i16; 3], temp: i8, timestamp: u16) -> [u8; 16] {
    packet_with_header(0x68, accel, gyro, temp, timestamp)
}

pub fn packet_with_header(
    header: u8,
    accel: [i16; 3],
    gyro: [i16; 3],
    temp: i8,
    timestamp: u16,
) -> [u8; 16] {
    let mut p = [0u8; 16];
    p[0] = header;
    for (i, v) in accel.iter().chain(&gyro).enumerate() {
        p[1 + 2 * i..3 + 2 * i].copy_from_slice(&v.to_be_bytes());
    }
    p[13] = temp as u8;
    p[14..16].copy_from_slice(&timestamp.to_be_bytes());
    p
}

/// FIFO_COUNTH/L (0x2E, 2 bytes big-endian, bytes) then one burst of FIFO_DATA (0x30).
pub fn fifo_read(packets: &[[u8; 16]]) -> Vec<T> {
    let count = (packets.len() * 16) as u16;
    let mut t = r(0x2E, &count.to_be_bytes());
    if !packets.is_empty() {
        t.extend(r(0x30, &packets.concat()));
    }
    t
}
