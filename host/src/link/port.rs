//! The serial device: raw mode, a reader thread that splits the byte stream into frames and
//! decodes them, and the writer half.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use msreg_protocol::{frame, Deframer, DeviceMsg, FrameError, Packet, Pushed, DEVICE_FRAME_MAX};

use super::LinkError;

/// What the reader thread saw.
#[derive(Debug, Clone)]
pub enum Incoming {
    /// A decoded frame and when its first byte was read (clock sync: the device stamps its
    /// reply just before that byte, so a frame-start stamp leaves the reply's transfer time
    /// out of the round trip's backward half).
    Packet(Instant, Packet<DeviceMsg>),
    /// A frame that failed to decode.
    Bad(Instant, FrameError),
    /// The device closed or failed; the reader stopped.
    Closed(CloseReason),
}

/// Why the reader thread stopped.
#[derive(Debug, Clone, thiserror::Error)]
pub enum CloseReason {
    /// The thread ended (its channel is gone).
    #[error("reader thread ended")]
    ReaderEnded,
    /// A read failed.
    #[error("{message}")]
    Read {
        /// The kind of the I/O error.
        kind: std::io::ErrorKind,
        /// The I/O error's text (from the OS).
        message: String,
    },
}

/// An open serial device.
pub struct Port {
    name: String,
    writer: serialport::TTYPort,
    rx: Receiver<Incoming>,
    stop: Arc<AtomicBool>,
    reader: Option<JoinHandle<()>>,
}

impl Port {
    /// Opens `path` (a tty or pty) in raw mode and starts the reader.
    pub fn open(path: &str) -> Result<Self, LinkError> {
        let err = |e: serialport::Error| LinkError::Port {
            port: path.to_string(),
            message: e.to_string(),
        };
        let writer = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(50))
            .open_native()
            .map_err(err)?;
        let reader_port = writer.try_clone_native().map_err(err)?;
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let stop_reader = Arc::clone(&stop);
        let reader = std::thread::Builder::new()
            .name("msreg-link-rx".into())
            .spawn(move || read_loop(reader_port, &tx, &stop_reader))
            .map_err(|e| LinkError::Port {
                port: path.to_string(),
                message: format!("cannot start the reader thread: {e}"),
            })?;
        Ok(Self {
            name: path.to_string(),
            writer,
            rx,
            stop,
            reader: Some(reader),
        })
    }

    /// Device path.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Writes all of `bytes`.
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let mut rest = bytes;
        let deadline = Instant::now() + Duration::from_secs(10);
        while !rest.is_empty() {
            match self.writer.write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(LinkError::Port {
                        port: self.name.clone(),
                        message: format!("write failed: {e}"),
                    })
                }
            }
            if Instant::now() > deadline {
                return Err(LinkError::Timeout {
                    port: self.name.clone(),
                    awaited: super::Awaited::Write,
                    waited_s: 10.0,
                });
            }
        }
        Ok(())
    }

    /// Next incoming item, waiting at most `timeout`.
    pub fn recv(&self, timeout: Duration) -> Option<Incoming> {
        match self.rx.recv_timeout(timeout) {
            Ok(i) => Some(i),
            Err(mpsc::RecvTimeoutError::Timeout) => None,
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                Some(Incoming::Closed(CloseReason::ReaderEnded))
            }
        }
    }
}

impl Drop for Port {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.reader.take() {
            let _ = h.join();
        }
    }
}

fn read_loop(mut port: serialport::TTYPort, tx: &Sender<Incoming>, stop: &AtomicBool) {
    let mut deframer = Deframer::<DEVICE_FRAME_MAX>::new();
    let mut started: Option<Instant> = None;
    let mut buf = [0u8; 1024];
    while !stop.load(Ordering::Relaxed) {
        let n = match port.read(&mut buf) {
            Ok(0) => continue,
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                        | std::io::ErrorKind::WouldBlock
                ) =>
            {
                continue
            }
            Err(e) => {
                let _ = tx.send(Incoming::Closed(CloseReason::Read {
                    kind: e.kind(),
                    message: e.to_string(),
                }));
                return;
            }
        };
        let now = Instant::now();
        for &b in &buf[..n] {
            if b != 0 && started.is_none() {
                started = Some(now);
            }
            let item = match deframer.push(b) {
                Pushed::Pending => continue,
                Pushed::Oversize => {
                    started = None;
                    Incoming::Bad(now, FrameError::Oversize)
                }
                Pushed::Frame(f) => match frame::decode::<DeviceMsg>(f) {
                    Ok(p) => Incoming::Packet(started.take().unwrap_or(now), p),
                    Err(e) => {
                        started = None;
                        Incoming::Bad(now, e)
                    }
                },
            };
            if tx.send(item).is_err() {
                return;
            }
        }
    }
    // Keep the port's settings unchanged for the next user.
    let _ = port.flush();
}
