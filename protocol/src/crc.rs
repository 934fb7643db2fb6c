//! CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, no final xor), table driven.
//! Check value: `crc16(b"123456789") == 0x29B1`.
//!
//! ```
//! assert_eq!(msreg_protocol::crc::crc16(b"123456789"), 0x29B1);
//! ```

const POLY: u16 = 0x1021;

const TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ POLY
            } else {
                c << 1
            };
            bit += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// CRC-16/CCITT-FALSE of `data`.
pub fn crc16(data: &[u8]) -> u16 {
    data.iter().fold(0xFFFF, |crc, &b| {
        (crc << 8) ^ TABLE[usize::from((crc >> 8) as u8 ^ b)]
    })
}
