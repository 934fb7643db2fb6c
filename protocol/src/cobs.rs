//! Consistent Overhead Byte Stuffing: removes every `0x00` from a payload so that `0x00` can
//! delimit frames. Encoding `n` bytes adds at most `n / 254 + 1` bytes.
//!
//! ```
//! let mut out = [0u8; 8];
//! let n = msreg_protocol::cobs::encode(&[0x11, 0x00, 0x22], &mut out).unwrap();
//! assert_eq!(&out[..n], &[0x02, 0x11, 0x02, 0x22]);
//! let m = msreg_protocol::cobs::decode_in_place(&mut out[..n]).unwrap();
//! assert_eq!(&out[..m], &[0x11, 0x00, 0x22]);
//! ```

/// Largest COBS encoding of `n` bytes.
pub const fn max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Encodes `input` into `out`; returns the encoded length, or `None` if `out` is too small.
///
/// Canonical COBS: a payload that ends with a full block of 254 non-zero bytes ends with
/// that block (no trailing `0x01`), as the `cobs` crate writes it (`tests/cobs_crate.rs`).
pub fn encode(input: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut block = Block::new();
    for &b in input {
        block.push(b, |i, v| out.get_mut(i).map(|slot| *slot = v))?;
    }
    block.finish(|i, v| out.get_mut(i).map(|slot| *slot = v))
}

/// Encodes `buf[start..start + n]` into the front of `buf` (the write position never passes
/// the read position when `start` exceeds the overhead, `n / 254 + 1`); returns the encoded
/// length, or `None` if `buf` is too short or `start` too small. One frame buffer serves
/// both the payload and its encoding, which is why the frame does not use the `cobs` crate:
/// it encodes into a second buffer only (docs/protocol.md, "COBS").
pub fn encode_in_place(buf: &mut [u8], start: usize, n: usize) -> Option<usize> {
    let end = start.checked_add(n)?;
    if end > buf.len() {
        return None;
    }
    let mut block = Block::new();
    for r in start..end {
        let b = buf[r];
        if block.write > r {
            return None;
        }
        block.push(b, |i, v| buf.get_mut(i).map(|slot| *slot = v))?;
    }
    block.finish(|i, v| buf.get_mut(i).map(|slot| *slot = v))
}

/// The encoder's state: where the open block's code byte goes, the next write position,
/// the open block's code, and whether a full block was just closed.
struct Block {
    code_at: usize,
    write: usize,
    code: u8,
    just_closed_full: bool,
}

impl Block {
    fn new() -> Self {
        Self {
            code_at: 0,
            write: 1,
            code: 1,
            just_closed_full: false,
        }
    }

    /// Appends one payload byte through `put(index, value)` (None when out of room).
    fn push(&mut self, b: u8, mut put: impl FnMut(usize, u8) -> Option<()>) -> Option<()> {
        self.just_closed_full = false;
        if b == 0 {
            return self.close(&mut put);
        }
        put(self.write, b)?;
        self.write += 1;
        self.code += 1;
        if self.code == 0xFF {
            self.close(&mut put)?;
            self.just_closed_full = true;
        }
        Some(())
    }

    fn close(&mut self, put: &mut impl FnMut(usize, u8) -> Option<()>) -> Option<()> {
        put(self.code_at, self.code)?;
        self.code_at = self.write;
        self.write += 1;
        self.code = 1;
        Some(())
    }

    /// Closes the last block; returns the encoded length.
    fn finish(mut self, mut put: impl FnMut(usize, u8) -> Option<()>) -> Option<usize> {
        if self.just_closed_full {
            // The payload ended with a full block: no empty block after it.
            return Some(self.write - 1);
        }
        self.close(&mut put)?;
        Some(self.write - 1)
    }
}

/// Decodes a COBS block (without its `0x00` delimiter) in place; returns the decoded length,
/// or `None` if the block is malformed (a zero byte, or a code running past the end).
pub fn decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let (mut r, mut w) = (0, 0);
    while r < buf.len() {
        let code = buf[r];
        if code == 0 {
            return None;
        }
        let end = r + usize::from(code);
        if end > buf.len() {
            return None;
        }
        r += 1;
        while r < end {
            let b = buf[r];
            if b == 0 {
                return None;
            }
            buf[w] = b;
            w += 1;
            r += 1;
        }
        if code != 0xFF && r < buf.len() {
            buf[w] = 0;
            w += 1;
        }
    }
    Some(w)
}
