//! The link client: handshake, sending with flow control, collecting what the device sends,
//! recording.
//!
//! Flow control: every host frame is acknowledged by the device. The client keeps at most
//! `window_bytes` of unacknowledged frames in flight (below the device's receive ring, so
//! the ring cannot overflow in normal operation). A frame not acknowledged within
//! `ack_timeout` is given up (counted in [`Collected::ack_timeouts`]) and the window moves
//! on: the session recovers from lost frames instead of stalling.

use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

use msreg_protocol::{
    frame, AckStatus, DeviceMsg, ErrorKind, ErrorReport, Estimate, HealthAlarm, Hello, HostMsg,
    Status, TimeSyncReply, TimeSyncRequest, UpdateDiagnostic, HOST_FRAME_MAX, VERSION,
};

use super::port::{Incoming, Port};
use super::record::{Header, Line, Recorder, Seq};
use super::LinkError;

/// Tuning of the client.
#[derive(Debug, Clone, Copy)]
pub struct ClientOptions {
    /// Most unacknowledged bytes in flight (0: half the device's receive buffer).
    pub window_bytes: usize,
    /// How long to wait for an acknowledgement.
    pub ack_timeout: Duration,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self {
            window_bytes: 0,
            ack_timeout: Duration::from_secs(2),
        }
    }
}

/// Everything the device sent, with host receive times (s since the session start).
#[derive(Debug, Clone, Default)]
pub struct Collected {
    /// The device's handshake.
    pub hello: Option<Hello>,
    /// Estimates.
    pub estimates: Vec<(f64, Estimate)>,
    /// Update diagnostics.
    pub diagnostics: Vec<(f64, UpdateDiagnostic)>,
    /// Health alarms.
    pub alarms: Vec<(f64, HealthAlarm)>,
    /// Error reports.
    pub errors: Vec<(f64, ErrorReport)>,
    /// Last status.
    pub status: Option<Status>,
    /// Acks received: ok, duplicate, rejected.
    pub acks: [u64; 3],
    /// Frames whose ack never came.
    pub ack_timeouts: u64,
    /// Device frames that failed to decode on the host.
    pub bad_frames: u64,
    /// Latency from sending a frame to receiving the estimate it produced, s.
    pub estimate_latency_s: Vec<f64>,
    /// Round trip from sending a frame to its ack, s.
    pub ack_latency_s: Vec<f64>,
    /// Clock-sync replies.
    pub time_syncs: Vec<(f64, TimeSyncReply)>,
}

impl Collected {
    /// Error reports of one kind.
    pub fn errors_of(&self, kind: ErrorKind) -> usize {
        self.errors.iter().filter(|(_, e)| e.kind == kind).count()
    }
}

/// One clock-sync exchange as the client saw it: its own instants around the device's stamps.
#[derive(Debug, Clone, Copy)]
pub struct TimedExchange {
    /// Just before the request was written.
    pub sent: Instant,
    /// When the reader thread read the reply's first byte.
    pub received: Instant,
    /// The device's reply.
    pub reply: TimeSyncReply,
}

struct InFlight {
    seq: u32,
    len: usize,
    sent: Instant,
}

/// A session with the device.
pub struct Client {
    port: Port,
    options: ClientOptions,
    start: Instant,
    next_seq: u32,
    in_flight: VecDeque<InFlight>,
    sent_at: HashMap<u32, Instant>,
    recorder: Option<Recorder>,
    /// What arrived so far.
    pub collected: Collected,
    /// Frames and bytes sent.
    pub sent: (u64, u64),
    closed: Option<super::port::CloseReason>,
    /// Clock-sync requests awaiting their reply (by `t1_ns`), and the last reply matched.
    sync_sent: HashMap<u64, Instant>,
    sync_done: Option<TimedExchange>,
}

impl Client {
    /// Opens the port; records to `record` when given.
    pub fn connect(
        path: &str,
        options: ClientOptions,
        record: Option<(&std::path::Path, &str)>,
    ) -> Result<Self, LinkError> {
        let port = Port::open(path)?;
        let recorder = match record {
            Some((file, command)) => Some(Recorder::create(
                file,
                Header {
                    protocol_version: VERSION,
                    port: path.to_string(),
                    command: command.to_string(),
                    started_unix_s: std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .map_or(0.0, |d| d.as_secs_f64()),
                },
            )?),
            None => None,
        };
        Ok(Self {
            port,
            options,
            start: Instant::now(),
            next_seq: 1,
            in_flight: VecDeque::new(),
            sent_at: HashMap::new(),
            recorder,
            collected: Collected::default(),
            sent: (0, 0),
            closed: None,
            sync_sent: HashMap::new(),
            sync_done: None,
        })
    }

    /// Seconds since the session started.
    pub fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Whether IMU batches are recorded (default yes).
    pub fn record_imu(&mut self, yes: bool) {
        if let Some(r) = self.recorder.as_mut() {
            r.record_imu = yes;
        }
    }

    /// Handshake: sends Hello until the device answers (up to `timeout`); checks the version.
    pub fn handshake(&mut self, timeout: Duration) -> Result<Hello, LinkError> {
        let deadline = Instant::now() + timeout;
        self.collected.hello = None;
        while Instant::now() < deadline {
            let hello = HostMsg::Hello(Hello {
                version: VERSION,
                max_frame: msreg_protocol::DEVICE_FRAME_MAX as u16,
                rx_buffer: 4096,
            });
            // Leading delimiters end any partial frame the device holds.
            self.port.write(&[0, 0])?;
            self.send_untracked(&hello)?;
            let wait_until = Instant::now() + Duration::from_millis(500);
            while Instant::now() < wait_until {
                self.pump(Duration::from_millis(20))?;
                if let Some(h) = self.collected.hello.filter(|_| self.saw_ack_for_hello()) {
                    if h.version != VERSION {
                        return Err(LinkError::Version {
                            device: h.version,
                            host: VERSION,
                        });
                    }
                    return Ok(h);
                }
            }
        }
        Err(LinkError::Timeout {
            port: self.port.name().to_string(),
            awaited: super::Awaited::Hello,
            waited_s: timeout.as_secs_f64(),
        })
    }

    fn saw_ack_for_hello(&self) -> bool {
        self.collected.acks.iter().sum::<u64>() > 0
    }

    fn window(&self) -> usize {
        if self.options.window_bytes > 0 {
            return self.options.window_bytes;
        }
        let device = self
            .collected
            .hello
            .map_or(4096, |h| usize::from(h.rx_buffer));
        (device / 2).max(HOST_FRAME_MAX)
    }

    fn encode(&mut self, msg: &HostMsg) -> (u32, Vec<u8>) {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        let mut buf = [0u8; HOST_FRAME_MAX];
        // HOST_FRAME_MAX is the MaxSize bound of every HostMsg: encoding cannot fail.
        let n = frame::encode(seq, msg, &mut buf).unwrap_or(0);
        (seq, buf[..n].to_vec())
    }

    fn record(&mut self, line: Line) -> Result<(), LinkError> {
        match self.recorder.as_mut() {
            Some(r) => r.line(&line),
            None => Ok(()),
        }
    }

    fn send_untracked(&mut self, msg: &HostMsg) -> Result<u32, LinkError> {
        let (seq, bytes) = self.encode(msg);
        self.port.write(&bytes)?;
        self.sent.0 += 1;
        self.sent.1 += bytes.len() as u64;
        self.sent_at.insert(seq, Instant::now());
        let t = self.now_s();
        self.record(Line::Tx {
            t,
            tx: Seq { seq, msg: *msg },
        })?;
        Ok(seq)
    }

    /// Sends `msg` once the window has room; returns its sequence number.
    pub fn send(&mut self, msg: &HostMsg) -> Result<u32, LinkError> {
        let (seq, bytes) = self.encode(msg);
        self.write_tracked(seq, &bytes)?;
        let t = self.now_s();
        self.record(Line::Tx {
            t,
            tx: Seq { seq, msg: *msg },
        })?;
        Ok(seq)
    }

    /// Sends already-encoded frame bytes under sequence number `seq` through the window
    /// (fault injection: duplicated frames).
    pub fn write_tracked(&mut self, seq: u32, bytes: &[u8]) -> Result<(), LinkError> {
        self.wait_for_room(bytes.len())?;
        self.port.write(bytes)?;
        self.sent.0 += 1;
        self.sent.1 += bytes.len() as u64;
        let now = Instant::now();
        self.sent_at.insert(seq, now);
        self.in_flight.push_back(InFlight {
            seq,
            len: bytes.len(),
            sent: now,
        });
        Ok(())
    }

    /// Writes raw bytes, outside flow control and unrecorded (fault injection).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.port.write(bytes)?;
        self.sent.1 += bytes.len() as u64;
        Ok(())
    }

    /// Encodes `msg` with the next sequence number without sending it (fault injection).
    pub fn encode_next(&mut self, msg: &HostMsg) -> (u32, Vec<u8>) {
        self.encode(msg)
    }

    fn in_flight_bytes(&self) -> usize {
        self.in_flight.iter().map(|f| f.len).sum()
    }

    fn wait_for_room(&mut self, len: usize) -> Result<(), LinkError> {
        self.pump(Duration::ZERO)?;
        while !self.in_flight.is_empty() && self.in_flight_bytes() + len > self.window() {
            self.expire();
            self.pump(Duration::from_millis(5))?;
        }
        Ok(())
    }

    /// Gives up frames whose ack is overdue.
    fn expire(&mut self) {
        let timeout = self.options.ack_timeout;
        let before = self.in_flight.len();
        self.in_flight.retain(|f| f.sent.elapsed() < timeout);
        self.collected.ack_timeouts += (before - self.in_flight.len()) as u64;
    }

    /// Waits until every frame is acknowledged (or given up) and `quiet` passed without
    /// input, at most `timeout`.
    pub fn flush(&mut self, timeout: Duration) -> Result<(), LinkError> {
        let deadline = Instant::now() + timeout;
        while !self.in_flight.is_empty() && Instant::now() < deadline {
            self.expire();
            self.pump(Duration::from_millis(10))?;
        }
        Ok(())
    }

    /// One clock-sync exchange: waits for room in the window, writes a `TimeSync` request
    /// (its `t1_ns`: ns since the session started) and waits up to `timeout` for the reply;
    /// `None` when it did not come (lost; the exchange is simply skipped).
    pub fn time_sync(&mut self, timeout: Duration) -> Result<Option<TimedExchange>, LinkError> {
        self.wait_for_room(HOST_FRAME_MAX.min(16))?;
        let t1_ns = self.start.elapsed().as_nanos() as u64;
        let (seq, bytes) = self.encode(&HostMsg::TimeSync(TimeSyncRequest { t1_ns }));
        let sent = Instant::now();
        self.port.write(&bytes)?;
        self.sent.0 += 1;
        self.sent.1 += bytes.len() as u64;
        self.sent_at.insert(seq, sent);
        self.in_flight.push_back(InFlight {
            seq,
            len: bytes.len(),
            sent,
        });
        self.sync_sent.insert(t1_ns, sent);
        let t = self.now_s();
        self.record(Line::Tx {
            t,
            tx: Seq {
                seq,
                msg: HostMsg::TimeSync(TimeSyncRequest { t1_ns }),
            },
        })?;
        let deadline = sent + timeout;
        while Instant::now() < deadline {
            self.pump(Duration::from_millis(1))?;
            if let Some(done) = self.sync_done.take() {
                if done.reply.t1_ns == t1_ns {
                    return Ok(Some(done));
                }
            }
        }
        self.sync_sent.remove(&t1_ns);
        Ok(None)
    }

    /// Asks for the device's counters.
    pub fn status(&mut self, timeout: Duration) -> Result<Status, LinkError> {
        self.collected.status = None;
        let deadline = Instant::now() + timeout;
        self.send(&HostMsg::GetStatus)?;
        let mut resent = false;
        while Instant::now() < deadline {
            self.pump(Duration::from_millis(10))?;
            if let Some(s) = self.collected.status {
                return Ok(s);
            }
            if !resent && Instant::now() + timeout / 2 > deadline {
                resent = true;
                self.send(&HostMsg::GetStatus)?;
            }
        }
        Err(LinkError::Timeout {
            port: self.port.name().to_string(),
            awaited: super::Awaited::Status,
            waited_s: timeout.as_secs_f64(),
        })
    }

    /// Processes what arrived, waiting up to `wait` for the first item.
    pub fn pump(&mut self, wait: Duration) -> Result<(), LinkError> {
        let mut wait = wait;
        while let Some(item) = self.port.recv(wait) {
            wait = Duration::ZERO;
            self.on_incoming(item)?;
        }
        if let Some(reason) = &self.closed {
            return Err(LinkError::Closed {
                port: self.port.name().to_string(),
                reason: reason.clone(),
            });
        }
        Ok(())
    }

    fn on_incoming(&mut self, item: Incoming) -> Result<(), LinkError> {
        match item {
            Incoming::Closed(why) => {
                self.closed = Some(why);
                Ok(())
            }
            Incoming::Bad(at, e) => {
                self.collected.bad_frames += 1;
                let t = at.duration_since(self.start).as_secs_f64();
                self.record(Line::Bad {
                    t,
                    bad: e.to_string(),
                })
            }
            Incoming::Packet(at, p) => {
                let t = at.duration_since(self.start).as_secs_f64();
                self.on_message(at, t, &p.msg);
                self.record(Line::Rx {
                    t,
                    rx: Seq {
                        seq: p.seq,
                        msg: p.msg,
                    },
                })
            }
        }
    }

    fn on_message(&mut self, at: Instant, t: f64, msg: &DeviceMsg) {
        let c = &mut self.collected;
        match *msg {
            DeviceMsg::Hello(h) => c.hello = Some(h),
            DeviceMsg::Ack(a) => {
                let i = match a.status {
                    AckStatus::Ok => 0,
                    AckStatus::Duplicate => 1,
                    AckStatus::Rejected => 2,
                };
                c.acks[i] += 1;
                if let Some(pos) = self.in_flight.iter().position(|f| f.seq == a.seq) {
                    if let Some(f) = self.in_flight.remove(pos) {
                        c.ack_latency_s
                            .push(at.duration_since(f.sent).as_secs_f64());
                    }
                }
            }
            DeviceMsg::Estimate(e) => {
                if let Some(sent) = self.sent_at.get(&e.last_seq) {
                    c.estimate_latency_s
                        .push(at.saturating_duration_since(*sent).as_secs_f64());
                }
                c.estimates.push((t, e));
            }
            DeviceMsg::UpdateDiagnostic(d) => c.diagnostics.push((t, d)),
            DeviceMsg::HealthAlarm(a) => c.alarms.push((t, a)),
            DeviceMsg::ErrorReport(e) => c.errors.push((t, e)),
            DeviceMsg::Status(s) => c.status = Some(s),
            DeviceMsg::TimeSync(r) => {
                c.time_syncs.push((t, r));
                if let Some(sent) = self.sync_sent.remove(&r.t1_ns) {
                    self.sync_done = Some(TimedExchange {
                        sent,
                        received: at,
                        reply: r,
                    });
                }
            }
        }
    }

    /// Flushes the recording.
    pub fn finish(&mut self) -> Result<(), LinkError> {
        match self.recorder.as_mut() {
            Some(r) => r.flush(),
            None => Ok(()),
        }
    }
}
