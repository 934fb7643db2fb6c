//! FIFO packet 3 (datasheet section 6.1): header, accel X/Y/Z, gyro X/Y/Z (16 bit
//! big-endian each), temperature (8 bit) and a 16-bit time stamp: 16 bytes.

use crate::config::Config;
use crate::regs::header;

/// Bytes of packet 3.
pub const PACKET_LEN: usize = 16;
/// FIFO size, bytes: a larger `FIFO_COUNT` is not a count the part can report.
pub const FIFO_BYTES: u16 = 2048;
/// Value of a sensor channel that holds no valid sample (sensor off or not yet settled).
pub const INVALID_SAMPLE: i16 = i16::MIN;

/// One packet 3 as read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawPacket {
    /// Header byte.
    pub header: u8,
    /// Accelerometer X, Y, Z, LSB.
    pub accel: [i16; 3],
    /// Gyro X, Y, Z, LSB.
    pub gyro: [i16; 3],
    /// `FIFO_TEMP_DATA` (8 bit).
    pub temperature: i8,
    /// The packet's time stamp on the IMU's own clock (`TMST`, 16 bit, 1 us per LSB with
    /// the reset `TMST_CONFIG`); wraps every 65.5 ms.
    pub timestamp: u16,
}

/// What a 16-byte slot of the FIFO holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Packet {
    /// `HEADER_MSG` set: the FIFO was empty.
    Empty,
    /// A packet with accel and gyro data.
    Data(RawPacket),
    /// A well-formed packet whose accel or gyro holds the invalid marker -32768.
    Invalid(RawPacket),
}

/// Parses one packet 3. `Err(header)` when the header is not that of packet 3 (accel and
/// gyro present, 16-bit data, FIFO not empty): the byte stream is out of step or corrupt.
pub fn parse(bytes: &[u8; PACKET_LEN]) -> Result<Packet, u8> {
    let h = bytes[0];
    if h & header::MSG != 0 {
        return Ok(Packet::Empty);
    }
    if h & (header::ACCEL | header::GYRO | header::HIRES) != header::ACCEL | header::GYRO {
        return Err(h);
    }
    let word = |i: usize| i16::from_be_bytes([bytes[i], bytes[i + 1]]);
    let p = RawPacket {
        header: h,
        accel: [word(1), word(3), word(5)],
        gyro: [word(7), word(9), word(11)],
        temperature: i8::from_be_bytes([bytes[13]]),
        timestamp: u16::from_be_bytes([bytes[14], bytes[15]]),
    };
    if p.accel.contains(&INVALID_SAMPLE) || p.gyro.contains(&INVALID_SAMPLE) {
        Ok(Packet::Invalid(p))
    } else {
        Ok(Packet::Data(p))
    }
}

/// A sample in SI units, IMU axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Time of the sample on the caller's monotonic clock, ns ([`crate::Stamper`]).
    pub stamp_ns: u64,
    /// Specific force, m/s^2.
    pub accel: [f32; 3],
    /// Angular rate, rad/s.
    pub gyro: [f32; 3],
    /// Die temperature, deg C.
    pub temperature_c: f32,
    /// The packet's 16-bit time stamp on the IMU's clock (see [`RawPacket::timestamp`]).
    pub device_timestamp: u16,
}

impl Sample {
    /// Scales a packet with the ranges of `config`: LSB x full scale / 32768, the
    /// temperature as `FIFO_TEMP_DATA / 2.07 + 25` deg C.
    pub fn from_raw(p: &RawPacket, config: &Config, stamp_ns: u64) -> Self {
        let a = config.accel_range.m_per_s2_per_lsb();
        let g = config.gyro_range.rad_per_s_per_lsb();
        Self {
            stamp_ns,
            accel: p.accel.map(|v| f32::from(v) * a),
            gyro: p.gyro.map(|v| f32::from(v) * g),
            temperature_c: f32::from(p.temperature) / 2.07 + 25.0,
            device_timestamp: p.timestamp,
        }
    }
}
