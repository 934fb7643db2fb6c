//! msreg-protocol: the one definition of the serial link between `msreg link` (host) and the
//! firmware.
//!
//! A frame is `COBS(postcard(Packet) ++ CRC-16/CCITT-FALSE little-endian) ++ 0x00`
//! ([`frame`]); a [`Packet`] carries a sequence number and one message of
//! [`HostMsg`] (host to device) or [`DeviceMsg`] (device to host) ([`message`]). Every buffer
//! size follows from postcard's `MaxSize` at compile time; nothing allocates. The format is
//! written down in `docs/protocol.md` and pinned by exact-byte tests.
//!
//! ```
//! use msreg_protocol::{frame, HostMsg, Anchor, HOST_FRAME_MAX};
//! let mut out = [0u8; HOST_FRAME_MAX];
//! let n = frame::encode(7, &HostMsg::Anchor(Anchor { stamp_ns: 1, sensor: 0 }), &mut out).unwrap();
//! assert_eq!(&out[..n], &[0x04, 0x07, 0x03, 0x01, 0x03, 0x8c, 0xbf, 0x00]);
//! let packet = frame::decode::<HostMsg>(&mut out[..n - 1]).unwrap();
//! assert_eq!(packet.seq, 7);
//! ```
#![no_std]
#![warn(missing_docs)]
#![cfg_attr(not(test), warn(clippy::unwrap_used))]

pub mod batch;
pub mod cobs;
pub mod crc;
pub mod frame;
pub mod message;

pub use batch::Bounded;
pub use frame::{Deframer, FrameError, Packet, Pushed};
pub use message::*;

use postcard::experimental::max_size::MaxSize;

/// Protocol version carried by [`Hello`]; bumped on any change of the wire format.
pub const VERSION: u16 = 5;

/// Largest encoded frame from the host, delimiter included.
pub const HOST_FRAME_MAX: usize = frame::frame_max(Packet::<HostMsg>::POSTCARD_MAX_SIZE);
/// Largest encoded frame from the device, delimiter included.
pub const DEVICE_FRAME_MAX: usize = frame::frame_max(Packet::<DeviceMsg>::POSTCARD_MAX_SIZE);
