//! `cobs.rs` against the `cobs` crate 0.3 (issue 16, item 6): the same bytes both ways on
//! arbitrary payloads (this found `cobs.rs` writing a superfluous `0x01` after a payload
//! that ends with a full 254-byte block, now canonical), the same refusals of malformed
//! blocks, and where they differ: an empty payload and a bare delimiter, neither of which
//! is a frame. Why the frame keeps its own encoder: docs/protocol.md, "COBS".

use msreg_protocol::cobs;
use proptest::prelude::*;

/// Payloads from 1 to 700 bytes with 0-50 % zeros (runs past 254 non-zero bytes included).
fn payload() -> impl Strategy<Value = Vec<u8>> {
    (1usize..700, 0u8..128).prop_flat_map(|(len, zero_in_256)| {
        proptest::collection::vec(
            any::<u8>().prop_map(move |b| if b < zero_in_256 { 0 } else { b.max(1) }),
            len,
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn encodings_are_identical_and_both_decode_back(v in payload()) {
        let mut ours = vec![0u8; cobs::max_encoded_len(v.len())];
        let mut theirs = vec![0u8; ::cobs::max_encoding_length(v.len())];
        let n = cobs::encode(&v, &mut ours).expect("room");
        let m = ::cobs::encode(&v, &mut theirs);
        prop_assert_eq!(&ours[..n], &theirs[..m]);
        let mut a = ours[..n].to_vec();
        let mut b = theirs[..m].to_vec();
        let na = cobs::decode_in_place(&mut a).expect("valid");
        let nb = ::cobs::decode_in_place(&mut b).expect("valid");
        prop_assert_eq!(&a[..na], &v[..]);
        prop_assert_eq!(&b[..nb], &v[..]);
    }
}

#[test]
fn malformed_blocks_are_refused_by_both() {
    for block in [&[0x03u8, 0x11, 0x00, 0x22][..], &[0x05, 0x11, 0x22]] {
        let (mut a, mut b) = (block.to_vec(), block.to_vec());
        assert_eq!(cobs::decode_in_place(&mut a), None, "{block:?}");
        assert!(::cobs::decode_in_place(&mut b).is_err(), "{block:?}");
    }
}

#[test]
fn a_lone_delimiter_is_malformed_here_and_an_empty_frame_there() {
    // The deframer strips the 0x00 delimiter, so a block that is a bare 0x00 cannot be a
    // frame; the crate reads it as the end of an empty frame.
    let (mut a, mut b) = ([0x00u8], [0x00u8]);
    assert_eq!(cobs::decode_in_place(&mut a), None);
    assert_eq!(::cobs::decode_in_place(&mut b).ok(), Some(0));
}

#[test]
fn only_the_empty_payload_differs() {
    // Canonical COBS encodes an empty packet as one code byte; the crate writes nothing and
    // refuses to decode that. No msreg frame is empty (each carries its CRC).
    let mut ours = [0u8; 2];
    assert_eq!(cobs::encode(&[], &mut ours), Some(1));
    assert_eq!(ours[0], 0x01);
    let mut theirs = [0u8; 2];
    assert_eq!(::cobs::encode(&[], &mut theirs), 0);
    assert!(::cobs::decode_in_place(&mut []).is_err());
}
