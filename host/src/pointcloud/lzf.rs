//! LZF decompression (Marc Lehmann's liblzf format), the codec of PCD
//! `binary_compressed` data.
//!
//! A control byte `c < 32` starts a literal run of `c + 1` bytes; otherwise
//! `c >> 5` is the back-reference length minus 2 (7 means "add the next
//! byte"), and `((c & 0x1f) << 8) + next + 1` is the distance back into the
//! output. References may overlap the bytes they produce.

/// Decompresses `input` into exactly `expected_len` bytes; `Err` says why the
/// stream is corrupt.
pub(crate) fn decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, String> {
    let mut out: Vec<u8> = Vec::with_capacity(expected_len);
    let mut ip = 0usize;
    while ip < input.len() {
        let ctrl = usize::from(input[ip]);
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            let literal = input.get(ip..ip + len).ok_or_else(|| {
                format!("literal run of {len} bytes at input byte {ip} overruns the input")
            })?;
            if out.len() + len > expected_len {
                return Err(format!("output exceeds the declared {expected_len} bytes"));
            }
            out.extend_from_slice(literal);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(ip).ok_or("input ends inside a back-reference")?);
                ip += 1;
            }
            len += 2;
            let low = usize::from(*input.get(ip).ok_or("input ends inside a back-reference")?);
            ip += 1;
            let distance = ((ctrl & 0x1f) << 8) + low + 1;
            let start = out.len().checked_sub(distance).ok_or_else(|| {
                format!("back-reference {distance} bytes before the output start")
            })?;
            if out.len() + len > expected_len {
                return Err(format!("output exceeds the declared {expected_len} bytes"));
            }
            for k in 0..len {
                let byte = out[start + k];
                out.push(byte);
            }
        }
    }
    if out.len() != expected_len {
        return Err(format!(
            "decompressed to {} bytes, header declares {expected_len}",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::decompress;

    #[test]
    fn literal_and_overlapping_back_reference_decode() {
        // "ab" literal, then a 6-byte reference at distance 2: "abababab".
        let stream = [1u8, b'a', b'b', 4 << 5, 1];
        assert_eq!(decompress(&stream, 8).unwrap(), b"abababab");
    }

    #[test]
    fn corrupt_streams_are_errors_not_panics() {
        assert!(decompress(&[5, b'a'], 6).is_err());
        assert!(decompress(&[(1 << 5) | 3, 0], 3).is_err());
        assert!(decompress(&[0, b'a'], 2).is_err());
    }
}
