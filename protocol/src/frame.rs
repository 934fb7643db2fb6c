//! Framing: `COBS(postcard(Packet) ++ crc16_le) ++ 0x00`.
//!
//! [`encode`] writes one frame; [`Deframer`] collects received bytes into frames within a
//! fixed buffer (an over-long frame is dropped up to the next delimiter and reported, never
//! stored); [`decode`] checks COBS, CRC and the postcard payload of one frame, in place.

use core::fmt;

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::cobs;
use crate::crc::crc16;

/// A message with the sender's sequence number.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Packet<M> {
    /// Sender's sequence number (wraps).
    pub seq: u32,
    /// The message.
    pub msg: M,
}

impl<M: MaxSize> MaxSize for Packet<M> {
    const POSTCARD_MAX_SIZE: usize = u32::POSTCARD_MAX_SIZE + M::POSTCARD_MAX_SIZE;
}

/// Bytes of the CRC trailer.
pub const CRC_LEN: usize = 2;

/// Largest frame (delimiter included) for a packet of at most `packet_max` bytes.
pub const fn frame_max(packet_max: usize) -> usize {
    cobs::max_encoded_len(packet_max + CRC_LEN) + 1
}

/// Why a frame could not be encoded or decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The output buffer is too small (encode).
    BufferTooSmall,
    /// Malformed COBS, or shorter than a CRC.
    Framing,
    /// CRC mismatch.
    Crc,
    /// The payload is not a valid packet (or has trailing bytes).
    Decode,
    /// More bytes than the receive buffer before a delimiter.
    Oversize,
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            FrameError::BufferTooSmall => "output buffer too small",
            FrameError::Framing => "malformed COBS frame",
            FrameError::Crc => "CRC mismatch",
            FrameError::Decode => "payload does not decode",
            FrameError::Oversize => "frame longer than the receive buffer",
        })
    }
}

/// Encodes `msg` with sequence number `seq` into `out` as one frame (delimiter included);
/// returns its length. `out` of [`crate::HOST_FRAME_MAX`] / [`crate::DEVICE_FRAME_MAX`]
/// bytes always suffices.
pub fn encode<M: Serialize>(seq: u32, msg: &M, out: &mut [u8]) -> Result<usize, FrameError> {
    // The packet is serialised behind room for the COBS overhead, then encoded forward into
    // the front of the same buffer: the write position never passes the read position.
    let overhead = out.len() / 254 + 2;
    let body_area = out.get_mut(overhead..).ok_or(FrameError::BufferTooSmall)?;
    let packet = Packet { seq, msg };
    let n = postcard::to_slice(&packet, body_area)
        .map_err(|_| FrameError::BufferTooSmall)?
        .len();
    let crc = crc16(&body_area[..n]);
    let body_end = overhead + n;
    if body_end + CRC_LEN > out.len() {
        return Err(FrameError::BufferTooSmall);
    }
    out[body_end..body_end + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    let len =
        cobs::encode_in_place(out, overhead, n + CRC_LEN).ok_or(FrameError::BufferTooSmall)?;
    *out.get_mut(len).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(len + 1)
}

/// Decodes one frame (without its delimiter) in place.
pub fn decode<'a, M: Deserialize<'a>>(frame: &'a mut [u8]) -> Result<Packet<M>, FrameError> {
    let n = cobs::decode_in_place(frame).ok_or(FrameError::Framing)?;
    if n <= CRC_LEN {
        return Err(FrameError::Framing);
    }
    let (body, crc) = frame[..n].split_at(n - CRC_LEN);
    if crc16(body) != u16::from_le_bytes([crc[0], crc[1]]) {
        return Err(FrameError::Crc);
    }
    match postcard::take_from_bytes::<Packet<M>>(body) {
        Ok((packet, [])) => Ok(packet),
        _ => Err(FrameError::Decode),
    }
}

/// What [`Deframer::push`] made of a byte.
#[derive(Debug, PartialEq, Eq)]
pub enum Pushed<'a> {
    /// Inside a frame, or an empty frame (repeated delimiters resynchronise).
    Pending,
    /// A complete frame (COBS-encoded, delimiter stripped): pass it to [`decode`].
    Frame(&'a mut [u8]),
    /// A frame longer than `N` bytes ended; it was dropped.
    Oversize,
}

/// Splits a byte stream at `0x00` into frames of at most `N` bytes. Memory is `N` bytes,
/// whatever arrives.
pub struct Deframer<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflowed: bool,
}

impl<const N: usize> Default for Deframer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Deframer<N> {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
        }
    }

    /// Forgets a partial frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Takes one received byte.
    pub fn push(&mut self, byte: u8) -> Pushed<'_> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) if !self.overflowed => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => self.overflowed = true,
            }
            return Pushed::Pending;
        }
        let (len, overflowed) = (self.len, self.overflowed);
        self.reset();
        if overflowed {
            Pushed::Oversize
        } else if len == 0 {
            Pushed::Pending
        } else {
            Pushed::Frame(&mut self.buf[..len])
        }
    }
}
