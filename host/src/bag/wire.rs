//! The two wire formats of ROS messages, read field by field:
//!
//! - ROS 1 serialisation: little-endian, packed (no alignment), strings and variable arrays
//!   as a `uint32` length then the bytes, no terminator; `Header` is `seq, stamp, frame_id`.
//! - ROS 2 CDR (OMG XCDR1 `CDR_LE`/`CDR_BE`, and XCDR2 `CDR2_LE`/`CDR2_BE`): a 4-byte
//!   encapsulation header, then each primitive aligned to its size (at most 4 in XCDR2),
//!   counted from the end of the encapsulation header; strings as a `uint32` length that
//!   includes the terminating NUL; `Header` is `stamp, frame_id` (no `seq`).
//!
//! `time` is two 32-bit words (seconds, nanoseconds) in both.

use super::error::DecodeError;

/// Which serialisation a message is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// ROS 1 (`.bag`, or MCAP message encoding `ros1`).
    Ros1,
    /// ROS 2 CDR (MCAP message encoding `cdr`).
    Cdr,
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Header {
    /// Stamp, ns since the epoch (0 when the publisher left it unset).
    pub stamp_ns: u64,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

/// A cursor over one serialised message.
#[derive(Debug)]
pub struct WireReader<'a> {
    data: &'a [u8],
    pos: usize,
    /// Alignment origin (CDR: just after the encapsulation header).
    origin: usize,
    /// Largest alignment (8 in XCDR1, 4 in XCDR2, 1 in ROS 1).
    max_align: usize,
    big_endian: bool,
    dialect: Dialect,
}

impl<'a> WireReader<'a> {
    /// A reader of `data` in `dialect`; CDR data starts with its encapsulation header.
    pub fn new(data: &'a [u8], dialect: Dialect) -> Result<Self, DecodeError> {
        let mut reader = Self {
            data,
            pos: 0,
            origin: 0,
            max_align: 1,
            big_endian: false,
            dialect,
        };
        if dialect == Dialect::Cdr {
            let head = reader.take(4)?;
            let id = u16::from_be_bytes([head[0], head[1]]);
            (reader.big_endian, reader.max_align) = match id {
                0x0000 => (true, 8),
                0x0001 => (false, 8),
                0x0006 | 0x000a => (true, 4),
                0x0007 | 0x000b => (false, 4),
                _ => return Err(DecodeError::CdrRepresentation { id }),
            };
            reader.origin = 4;
        }
        Ok(reader)
    }

    /// The dialect being read.
    pub fn dialect(&self) -> Dialect {
        self.dialect
    }

    /// Whether multi-byte values are big-endian (CDR_BE).
    pub fn big_endian(&self) -> bool {
        self.big_endian
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let at = self.pos;
        let bytes = at
            .checked_add(n)
            .and_then(|end| self.data.get(at..end))
            .ok_or(DecodeError::Truncated {
                at,
                need: n,
                len: self.data.len(),
            })?;
        self.pos = at + n;
        Ok(bytes)
    }

    fn align(&mut self, size: usize) -> Result<(), DecodeError> {
        let a = size.min(self.max_align);
        if a > 1 {
            let rel = self.pos - self.origin;
            let pad = (a - rel % a) % a;
            self.take(pad)?;
        }
        Ok(())
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        self.align(N)?;
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        if self.big_endian {
            out.reverse();
        }
        Ok(out)
    }

    /// `uint8` / `bool` / `char`.
    pub fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.array::<1>()?[0])
    }

    /// `uint32`.
    pub fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    /// `float64`.
    pub fn f64(&mut self) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.array()?))
    }

    /// `N` consecutive `float64` (a fixed-size array: no length prefix).
    pub fn f64s<const N: usize>(&mut self) -> Result<[f64; N], DecodeError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64()?;
        }
        Ok(out)
    }

    /// A sequence length (`uint32`).
    pub fn seq_len(&mut self) -> Result<usize, DecodeError> {
        Ok(self.u32()? as usize)
    }

    /// `uint8[]`: borrowed bytes.
    pub fn bytes(&mut self) -> Result<&'a [u8], DecodeError> {
        let n = self.seq_len()?;
        self.take(n)
    }

    /// `string`.
    pub fn string(&mut self) -> Result<String, DecodeError> {
        let at = self.pos;
        let n = self.seq_len()?;
        let mut bytes = self.take(n)?;
        if self.dialect == Dialect::Cdr {
            // The length counts the terminating NUL (0 for an empty string from some writers).
            match bytes.split_last() {
                Some((0, rest)) => bytes = rest,
                Some(_) => return Err(DecodeError::BadString { at }),
                None => {}
            }
        }
        std::str::from_utf8(bytes)
            .map(str::to_owned)
            .map_err(|_| DecodeError::BadString { at })
    }

    /// `time` / `builtin_interfaces/Time`: seconds and nanoseconds, as ns.
    pub fn time(&mut self) -> Result<u64, DecodeError> {
        let sec = self.u32()?;
        let nsec = self.u32()?;
        Ok(u64::from(sec) * 1_000_000_000 + u64::from(nsec))
    }

    /// `std_msgs/Header` of the dialect.
    pub fn header(&mut self) -> Result<Header, DecodeError> {
        if self.dialect == Dialect::Ros1 {
            let _seq = self.u32()?;
        }
        let stamp_ns = self.time()?;
        let frame_id = self.string()?;
        Ok(Header { stamp_ns, frame_id })
    }
}
