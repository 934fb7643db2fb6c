//! Session recordings: one JSON object per line, re-readable with [`read`].
//!
//! ```text
//! {"header":{"protocol_version":1,"port":"/dev/pts/3","command":"replay","started_unix_s":...}}
//! {"t":0.012,"tx":{"seq":1,"msg":{"Hello":{...}}}}
//! {"t":0.015,"rx":{"seq":0,"msg":{"Hello":{...}}}}
//! {"t":0.020,"bad":"CRC mismatch"}
//! ```
//! `t` is seconds since the session started (host clock); `msg` is the protocol message in
//! serde's externally tagged form.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use msreg_protocol::{DeviceMsg, HostMsg};
use serde::{Deserialize, Serialize};

use super::LinkError;

/// First line of a recording.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Header {
    /// Protocol version of the host.
    pub protocol_version: u16,
    /// Serial device.
    pub port: String,
    /// `replay` or `monitor`.
    pub command: String,
    /// Wall clock at the start, s since the Unix epoch.
    pub started_unix_s: f64,
}

/// A message with its sequence number.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Seq<M> {
    /// Sender's sequence number.
    pub seq: u32,
    /// Message.
    pub msg: M,
}

/// One line of a recording.
#[allow(clippy::large_enum_variant)] // short-lived values, one per line
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum Line {
    /// The header.
    Header {
        /// Header.
        header: Header,
    },
    /// Host to device.
    Tx {
        /// s since start.
        t: f64,
        /// Frame.
        tx: Seq<HostMsg>,
    },
    /// Device to host.
    Rx {
        /// s since start.
        t: f64,
        /// Frame.
        rx: Seq<DeviceMsg>,
    },
    /// A device frame that failed to decode.
    Bad {
        /// s since start.
        t: f64,
        /// Why.
        bad: String,
    },
}

/// Writes a recording.
pub struct Recorder {
    path: PathBuf,
    out: BufWriter<File>,
    /// Record host-to-device IMU batches too (large).
    pub record_imu: bool,
}

impl Recorder {
    /// Creates `path` and writes the header.
    pub fn create(path: &Path, header: Header) -> Result<Self, LinkError> {
        let file = File::create(path).map_err(|e| record_error(path, &e))?;
        let mut r = Self {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            record_imu: true,
        };
        r.line(&Line::Header { header })?;
        Ok(r)
    }

    /// Appends a line.
    pub fn line(&mut self, line: &Line) -> Result<(), LinkError> {
        if !self.record_imu {
            if let Line::Tx { tx, .. } = line {
                if matches!(tx.msg, HostMsg::ImuBatch(_)) {
                    return Ok(());
                }
            }
        }
        serde_json::to_writer(&mut self.out, line).map_err(|e| record_error(&self.path, &e))?;
        self.out
            .write_all(b"\n")
            .map_err(|e| record_error(&self.path, &e))
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), LinkError> {
        self.out.flush().map_err(|e| record_error(&self.path, &e))
    }
}

fn record_error(path: &Path, e: &dyn std::fmt::Display) -> LinkError {
    LinkError::Record {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Reads a recording; a malformed line is an error naming its line number.
pub fn read(path: &Path) -> Result<Vec<Line>, LinkError> {
    let file = File::open(path).map_err(|e| record_error(path, &e))?;
    let mut lines = Vec::new();
    for (i, line) in BufReader::new(file).lines().enumerate() {
        let line = line.map_err(|e| record_error(path, &e))?;
        if line.trim().is_empty() {
            continue;
        }
        let parsed = serde_json::from_str(&line).map_err(|e| LinkError::Record {
            path: format!("{}:{}", path.display(), i + 1),
            message: e.to_string(),
        })?;
        lines.push(parsed);
    }
    Ok(lines)
}
