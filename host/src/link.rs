//! `msreg link`: the host side of the serial link to the firmware (docs/protocol.md).
//!
//! - [`stream`] turns a dataset into the message sequence the firmware needs (the same
//!   initialisation and pose sequencing as `calibrate::pose_imu`);
//! - [`monitor_stream`] does it for a drive and the device's monitoring layout (the prior
//!   and pose sequencing of `msreg monitor`);
//! - [`port`] opens the serial device and decodes what arrives on a reader thread;
//! - [`clock_sync`] estimates the device clock from two-way exchanges (offset, skew);
//! - [`client`] sends with flow control (a window of unacknowledged bytes), collects the
//!   device's messages and records the session;
//! - [`record`] writes and re-reads session files (JSON lines);
//! - [`defmt`] decodes the firmware's log (QEMU's stdout) with the firmware's ELF;
//! - [`view`] draws the live monitor (full screen on a terminal, lines otherwise);
//! - [`cli`] is what `msreg link replay | monitor | show | log` run.

pub mod client;
pub mod clock_sync;
pub mod defmt;
pub mod monitor_stream;
pub mod port;
pub mod record;
mod session;
pub mod stamp_map;
pub mod stream;
pub mod view;

pub use client::{Client, ClientOptions, Collected};
pub use session::{
    dataset_stream, replay, replay_stream, show, ReplayOptions, ReplayOutcome, SyncOptions,
};
pub use stream::{build_stream, ReplayStream, StreamOptions};
pub use view::{final_estimates, live_view, summary};

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
    #[error("no answer from the device: {port}: {}", awaited.describe(*waited_s))]
    Timeout {
        /// Device path.
        port: String,
        /// What the host waited for.
        awaited: Awaited,
        /// How long it waited, s.
        waited_s: f64,
    },
    /// The reader thread stopped: the device closed or a read failed.
    #[error("{port}: closed: {reason}")]
    Closed {
        /// Device path.
        port: String,
        /// Why.
        reason: port::CloseReason,
    },
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
    /// A dataset file is missing or malformed (names the file and line).
    #[error(transparent)]
    Dataset(#[from] crate::dataset::DatasetError),
    /// The dataset does not give the filter what it needs.
    #[error(transparent)]
    Input(#[from] crate::calibrate::InputError),
    /// The camera images cannot be read or detected.
    #[error(transparent)]
    Camera(#[from] crate::vision::CameraInputError),
    /// A drive's files cannot be read.
    #[error(transparent)]
    Drive(#[from] crate::monitor::DriveFilesError),
    /// The monitor cannot start on this drive.
    #[error(transparent)]
    Monitor(#[from] crate::monitor::MonitorError),
    /// The monitor's filter tuning has a field the wire `Config` does not carry.
    #[error("the monitor's filter tuning has a field the protocol does not carry")]
    UntransmittedTuning,
}

/// What the host waited for when the device went quiet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Awaited {
    /// The device's `Hello` after opening the port.
    Hello,
    /// A `Status` after `GetStatus`.
    Status,
    /// The serial write to drain.
    Write,
}

impl Awaited {
    /// The words of a timeout after `waited_s`.
    fn describe(self, waited_s: f64) -> String {
        match self {
            Awaited::Hello => {
                format!("no Hello within {waited_s:.1} s (is the firmware running?)")
            }
            Awaited::Status => format!("no Status within {waited_s:.1} s"),
            Awaited::Write => format!("write blocked for {waited_s:.0} s"),
        }
    }
}
