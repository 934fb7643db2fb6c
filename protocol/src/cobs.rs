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
pub fn encode(input: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut code_at = 0;
    let mut w = 1;
    let mut code: u8 = 1;
    for &b in input {
        if b == 0 {
            *out.get_mut(code_at)? = code;
            code_at = w;
            w += 1;
            code = 1;
            continue;
        }
        *out.get_mut(w)? = b;
        w += 1;
        code += 1;
        if code == 0xFF {
            *out.get_mut(code_at)? = code;
            code_at = w;
            w += 1;
            code = 1;
        }
    }
    *out.get_mut(code_at)? = code;
    Some(w)
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
