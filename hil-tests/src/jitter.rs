//! A link with injected delay and jitter between the host client and QEMU's pty, and the
//! truth of the device clock seen from the QEMU side of it.
//!
//! The client opens [`JitterProxy::path`], one end of a pty pair; the proxy forwards every
//! chunk it reads to QEMU's pty (and back) after the chunk's delay: a floor plus a uniform
//! jitter plus, with probability `spike_p`, a spike (heavy tail). Bytes stay in order (a
//! chunk never overtakes the previous one), as on a serial line.
//!
//! Truth, by causality alone and without the injected delays: the proxy decodes the frames
//! it forwards. The device stamps a clock-sync request `t2` in its receive interrupt, after
//! the request's closing delimiter reached it, so after the proxy began writing that
//! delimiter to QEMU (`before_write`; written on its own, after a pause):
//! `device(before_write) <= t2`. It stamps its reply `t3` before writing the reply's first
//! byte, so before the proxy's read of that byte returned (`after_read`):
//! `device(after_read) >= t3`. Under QEMU without `-icount` the guest's SysTick runs on
//! QEMU's virtual clock, which is the host's `CLOCK_MONOTONIC` (Rust's `Instant`) plus a
//! constant: `device(i) = (i - epoch) + C`, and every exchange brackets `C`.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use msreg_protocol::{
    frame, Deframer, DeviceMsg, HostMsg, Pushed, DEVICE_FRAME_MAX, HOST_FRAME_MAX,
};
use serialport::{SerialPort, TTYPort};

/// Pause before a clock-sync request's delimiter is written (see `Ctx::write`).
const DELIMITER_PAUSE: Duration = Duration::from_micros(500);

/// Delay of one direction: `floor + U(0, jitter)`, plus a spike of `U(1, 10) x jitter`
/// with probability `spike_p`.
#[derive(Debug, Clone, Copy)]
pub struct Delay {
    /// Constant part.
    pub floor: Duration,
    /// Span of the uniform jitter.
    pub jitter: Duration,
    /// Probability of a spike per chunk.
    pub spike_p: f64,
}

impl Delay {
    fn draw(&self, rng: &mut u64) -> Duration {
        let j = self.jitter.as_secs_f64() * uniform(rng);
        let spike = if uniform(rng) < self.spike_p {
            self.jitter.as_secs_f64() * (1.0 + 9.0 * uniform(rng))
        } else {
            0.0
        };
        self.floor + Duration::from_secs_f64(j + spike)
    }
}

/// xorshift64*, in [0, 1).
fn uniform(state: &mut u64) -> f64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
}

/// The two directions' delays.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    /// Host to device.
    pub forward: Delay,
    /// Device to host.
    pub backward: Delay,
}

/// Bounds on `C` = device clock minus `Instant` ns since the proxy's epoch.
#[derive(Debug, Clone, Copy)]
pub struct TruthBracket {
    /// Largest lower bound, `max(t3 - after_read)`, ns.
    pub lower_ns: i64,
    /// Smallest upper bound, `min(t2 - before_write)`, ns.
    pub upper_ns: i64,
    /// Exchanges that gave both bounds.
    pub exchanges: usize,
}

#[derive(Default)]
struct Seen {
    /// `t1` of a request -> `before_write` ns since the epoch.
    written: std::collections::HashMap<u64, i64>,
    /// `(t1, t2, t3, after_read ns)` of every reply.
    replies: Vec<(u64, u64, u64, i64)>,
}

/// The proxy; stops (threads joined) on drop.
pub struct JitterProxy {
    /// The pty the client opens.
    pub path: String,
    /// `Instant` the truth's nanoseconds count from.
    pub epoch: Instant,
    shape: Arc<Mutex<Shape>>,
    seen: Arc<Mutex<Seen>>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    _slave: TTYPort,
}

fn open_raw(path: &str) -> Result<TTYPort, String> {
    serialport::new(path, 115_200)
        .timeout(Duration::from_millis(20))
        .open_native()
        .map_err(|e| format!("{path}: {e}"))
}

impl JitterProxy {
    /// Starts forwarding between a new pty pair and the device pty `device`.
    pub fn start(device: &str, shape: Shape, seed: u64) -> Result<Self, String> {
        let (master, slave) = TTYPort::pair().map_err(|e| format!("pty pair: {e}"))?;
        let path = slave.name().ok_or("pty without a name")?;
        let device_port = open_raw(device)?;
        let clone = |p: &TTYPort| p.try_clone_native().map_err(|e| e.to_string());
        let (master_w, device_w) = (clone(&master)?, clone(&device_port)?);
        let epoch = Instant::now();
        let shape = Arc::new(Mutex::new(shape));
        let seen = Arc::new(Mutex::new(Seen::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        for forward in [true, false] {
            let (tx, rx) = mpsc::channel::<(Instant, Vec<u8>)>();
            let (src, dst) = if forward {
                (clone(&master)?, clone(&device_w)?)
            } else {
                (clone(&device_port)?, clone(&master_w)?)
            };
            let ctx = Ctx {
                forward,
                epoch,
                shape: Arc::clone(&shape),
                seen: Arc::clone(&seen),
                stop: Arc::clone(&stop),
            };
            let reader_ctx = ctx.clone();
            let rng = seed.wrapping_mul(2).wrapping_add(u64::from(forward)) | 1;
            threads.push(std::thread::spawn(move || reader_ctx.read(src, &tx, rng)));
            threads.push(std::thread::spawn(move || ctx.write(dst, &rx)));
        }
        Ok(Self {
            path,
            epoch,
            shape,
            seen,
            stop,
            threads,
            _slave: slave,
        })
    }

    /// Changes the delays from now on.
    pub fn set_shape(&self, shape: Shape) {
        if let Ok(mut s) = self.shape.lock() {
            *s = shape;
        }
    }

    /// Forgets the exchanges seen so far (a new measurement phase).
    pub fn clear(&self) {
        if let Ok(mut s) = self.seen.lock() {
            *s = Seen::default();
        }
    }

    /// The bracket of `C` from every exchange seen since the last [`Self::clear`].
    pub fn truth(&self) -> TruthBracket {
        let Ok(seen) = self.seen.lock() else {
            return TruthBracket {
                lower_ns: i64::MIN,
                upper_ns: i64::MAX,
                exchanges: 0,
            };
        };
        let mut b = TruthBracket {
            lower_ns: i64::MIN,
            upper_ns: i64::MAX,
            exchanges: 0,
        };
        for &(t1, t2, t3, after_read) in &seen.replies {
            let Some(&before_write) = seen.written.get(&t1) else {
                continue;
            };
            b.lower_ns = b.lower_ns.max(t3 as i64 - after_read);
            b.upper_ns = b.upper_ns.min(t2 as i64 - before_write);
            b.exchanges += 1;
        }
        b
    }
}

impl Drop for JitterProxy {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[derive(Clone)]
struct Ctx {
    forward: bool,
    epoch: Instant,
    shape: Arc<Mutex<Shape>>,
    seen: Arc<Mutex<Seen>>,
    stop: Arc<AtomicBool>,
}

impl Ctx {
    fn ns(&self, at: Instant) -> i64 {
        at.saturating_duration_since(self.epoch).as_nanos() as i64
    }

    /// Reads chunks; device replies are noted at the read; each chunk is queued with its
    /// release time (never before the previous chunk's).
    fn read(&self, mut src: TTYPort, tx: &mpsc::Sender<(Instant, Vec<u8>)>, mut rng: u64) {
        let mut deframer = Deframer::<DEVICE_FRAME_MAX>::new();
        let mut started = None;
        let mut buf = [0u8; 4096];
        let mut last_release = Instant::now();
        while !self.stop.load(Ordering::Relaxed) {
            let n = match src.read(&mut buf) {
                Ok(n) if n > 0 => n,
                _ => continue,
            };
            let after_read = Instant::now();
            if !self.forward {
                self.note_replies((&mut deframer, &mut started), &buf[..n], after_read);
            }
            let shape = self.shape.lock().map(|s| *s).ok();
            let delay = shape.map_or(Duration::ZERO, |s| {
                if self.forward {
                    s.forward.draw(&mut rng)
                } else {
                    s.backward.draw(&mut rng)
                }
            });
            // Forward: the request's delimiter goes DELIMITER_PAUSE after its release (see
            // `write`), so the release is that much earlier: the delimiter keeps the delay.
            let delay = if self.forward {
                delay.saturating_sub(DELIMITER_PAUSE)
            } else {
                delay
            };
            last_release = last_release.max(after_read + delay);
            if tx.send((last_release, buf[..n].to_vec())).is_err() {
                return;
            }
        }
    }

    /// Notes each clock-sync reply with the read that returned its first byte.
    fn note_replies(
        &self,
        (deframer, started): (&mut Deframer<DEVICE_FRAME_MAX>, &mut Option<Instant>),
        bytes: &[u8],
        at: Instant,
    ) {
        for &b in bytes {
            if b != 0 && started.is_none() {
                *started = Some(at);
            }
            let Pushed::Frame(f) = deframer.push(b) else {
                if b == 0 {
                    *started = None;
                }
                continue;
            };
            let first = started.take().unwrap_or(at);
            if let Ok(DeviceMsg::TimeSync(r)) = frame::decode::<DeviceMsg>(f).map(|p| p.msg) {
                if let Ok(mut s) = self.seen.lock() {
                    s.replies.push((r.t1_ns, r.t2_ns, r.t3_ns, self.ns(first)));
                }
            }
        }
    }

    /// Writes each chunk at its release time. A clock-sync request's closing delimiter is
    /// written on its own, [`DELIMITER_PAUSE`] after the bytes before it (by then QEMU has
    /// taken them in), with `before_write` noted just before: the device's `t2` follows it by
    /// one byte's way through QEMU, not the whole frame's.
    fn write(&self, mut dst: TTYPort, rx: &mpsc::Receiver<(Instant, Vec<u8>)>) {
        let mut deframer = Deframer::<HOST_FRAME_MAX>::new();
        while !self.stop.load(Ordering::Relaxed) {
            let Ok((release, bytes)) = rx.recv_timeout(Duration::from_millis(20)) else {
                continue;
            };
            let now = Instant::now();
            if release > now {
                std::thread::sleep(release - now);
            }
            let mut from = 0;
            for (i, &b) in bytes.iter().enumerate() {
                if !self.forward {
                    break;
                }
                let Pushed::Frame(f) = deframer.push(b) else {
                    continue;
                };
                let Ok(HostMsg::TimeSync(r)) = frame::decode::<HostMsg>(f).map(|p| p.msg) else {
                    continue;
                };
                let _ = dst.write_all(&bytes[from..i]);
                // Spin, not sleep: a sleep overshoots by tens of microseconds, a floor the
                // backward direction would not have.
                let resume = Instant::now() + DELIMITER_PAUSE;
                while Instant::now() < resume {
                    std::hint::spin_loop();
                }
                let before_write = Instant::now();
                if let Ok(mut s) = self.seen.lock() {
                    s.written.insert(r.t1_ns, self.ns(before_write));
                }
                let _ = dst.write_all(&bytes[i..=i]);
                from = i + 1;
            }
            let _ = dst.write_all(&bytes[from..]);
        }
    }
}
