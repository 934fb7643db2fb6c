//! `msreg link`: the host side of the serial link to the firmware (docs/protocol.md).
//!
//! - [`stream`] turns a dataset into the message sequence the firmware needs (the same
//!   initialisation and pose sequencing as `calibrate::pose_imu`);
//! - [`monitor_stream`] does it for a drive and the device's monitoring layout (the prior
//!   and pose sequencing of `msreg monitor`);
//! - [`port`] opens the serial device and decodes what arrives on a reader thread;
//! - [`client`] sends with flow control (a window of unacknowledged bytes), collects the
//!   device's messages and records the session;
//! - [`record`] writes and re-reads session files (JSON lines);
//! - [`defmt`] decodes the firmware's log (QEMU's stdout) with the firmware's ELF;
//! - [`view`] draws the live monitor (full screen on a terminal, lines otherwise);
//! - [`cli`] is what `msreg link replay | monitor | show | log` run.

pub mod cli;
pub mod client;
pub mod defmt;
pub mod monitor_stream;
pub mod port;
pub mod record;
pub mod stream;
pub mod view;

pub use client::{Client, ClientOptions, Collected};
pub use stream::{build_stream, ReplayStream, StreamOptions};

/// Errors of the link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The serial device could not be opened or used.
    #[error("{port}: {message}")]
    Port {
        /// Device path.
        port: String,
        /// What failed.
        message: String,
    },
    /// The device did not answer in time.
    #[error("no answer from the device: {0}")]
    Timeout(String),
    /// The device speaks another protocol version.
    #[error("device protocol version {device}, host {host}")]
    Version {
        /// Device's version.
        device: u16,
        /// Ours.
        host: u16,
    },
    /// A recording could not be written or read.
    #[error("{path}: {message}")]
    Record {
        /// File.
        path: String,
        /// What failed.
        message: String,
    },
    /// The dataset cannot be replayed.
    #[error("{0}")]
    Dataset(String),
}
