//! A link with injected delay and jitter between the host client and QEMU's pty, and the
//! truth of the device clock seen from the QEMU side of it.
//!
//! The client opens [`JitterProxy::path`], one end of a pty pair; the proxy forwards every
//! chunk it reads to QEMU's pty (and back) after the chunk's delay: a floor plus a uniform
//! jitter plus, with probability `spike_p`, a spike (heavy tail), drawn from a seeded
//! generator per direction. Bytes stay in order (a chunk never overtakes the previous one),
//! as on a serial line.
//!
//! Truth, by causality alone and without the injected delays: the proxy decodes the frames
//! it forwards. The device stamps a clock-sync request `t2` in its receive interrupt when the
//! request's first byte reached it, so after the proxy began writing the chunk holding that
//! byte to QEMU (`before_write`): `device(before_write) <= t2`. It stamps its reply `t3`
//! before writing the reply's first byte, so before the proxy's read of that byte returned
//! (`after_read`): `device(after_read) >= t3`. Under QEMU without `-icount` the guest's
//! SysTick runs on QEMU's virtual clock, which is the host's `CLOCK_MONOTONIC` (Rust's
//! `Instant`) plus a constant: `device(i) = (i - epoch) + C`, and every exchange brackets
//! `C`. [`JitterProxy::legs`] gives every instant of every exchange, to see where each
//! direction's delay goes.

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

/// Lead of the wake-up delimiter before a forward chunk.
const WAKE_UP: Duration = Duration::from_micros(150);

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

/// The delays in force and their generators (xorshift states, forward and backward).
struct Link {
    shape: Shape,
    rng: [u64; 2],
}

impl Link {
    fn new(shape: Shape, seed: u64) -> Self {
        // Two odd, distinct, non-zero states, stirred so that nearby seeds part at once.
        let mut rng = [
            seed.wrapping_mul(2) | 1,
            seed.wrapping_mul(2).wrapping_add(3) | 1,
        ];
        for r in &mut rng {
            for _ in 0..8 {
                uniform(r);
            }
        }
        Self { shape, rng }
    }

    fn draw(&mut self, forward: bool) -> Duration {
        if forward {
            self.shape.forward.draw(&mut self.rng[0])
        } else {
            self.shape.backward.draw(&mut self.rng[1])
        }
    }
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
    /// `t1` of a request -> `before_write` of its first byte, ns since the epoch.
    written: std::collections::HashMap<u64, i64>,
    /// `(t1, t2, t3, after_read ns)` of every reply.
    replies: Vec<(u64, u64, u64, i64)>,
    /// `t1` of a request -> the proxy's read of its first byte, ns since the epoch.
    request_read: std::collections::HashMap<u64, i64>,
    /// `t1` of a reply -> the proxy's write of its first byte towards the host, ns.
    reply_written: std::collections::HashMap<u64, i64>,
}

/// The instants of one exchange on the proxy, ns since its epoch (diagnostics: where the
/// delays of each direction are spent).
#[derive(Debug, Clone, Copy)]
pub struct Legs {
    /// The request's `t1` (names the exchange).
    pub t1_ns: u64,
    /// Device stamps.
    pub t2_ns: u64,
    /// Device stamps.
    pub t3_ns: u64,
    /// Proxy read the request's first byte from the host side.
    pub request_read_ns: i64,
    /// Proxy began writing the request's first byte to QEMU.
    pub before_write_ns: i64,
    /// Proxy read the reply's first byte from QEMU.
    pub after_read_ns: i64,
    /// Proxy began writing the reply's first byte to the host side.
    pub reply_written_ns: i64,
}

/// The proxy; stops (threads joined) on drop.
pub struct JitterProxy {
    /// The pty the client opens.
    pub path: String,
    /// `Instant` the truth's nanoseconds count from.
    pub epoch: Instant,
    link: Arc<Mutex<Link>>,
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
    /// Starts forwarding between a new pty pair and the device pty `device`, the delays
    /// drawn from `seed`.
    pub fn start(device: &str, shape: Shape, seed: u64) -> Result<Self, String> {
        let (master, slave) = TTYPort::pair().map_err(|e| format!("pty pair: {e}"))?;
        let path = slave.name().ok_or("pty without a name")?;
        let device_port = open_raw(device)?;
        let clone = |p: &TTYPort| p.try_clone_native().map_err(|e| e.to_string());
        let (master_w, device_w) = (clone(&master)?, clone(&device_port)?);
        let epoch = Instant::now();
        let link = Arc::new(Mutex::new(Link::new(shape, seed)));
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
                link: Arc::clone(&link),
                seen: Arc::clone(&seen),
                stop: Arc::clone(&stop),
            };
            let reader_ctx = ctx.clone();
            threads.push(std::thread::spawn(move || reader_ctx.read(src, &tx)));
            threads.push(std::thread::spawn(move || ctx.write(dst, &rx)));
        }
        Ok(Self {
            path,
            epoch,
            link,
            seen,
            stop,
            threads,
            _slave: slave,
        })
    }

    /// Changes the delays from now on, drawn afresh from `seed`.
    pub fn set_shape(&self, shape: Shape, seed: u64) {
        if let Ok(mut l) = self.link.lock() {
            *l = Link::new(shape, seed);
        }
    }

    /// Forgets the exchanges seen so far (a new measurement phase).
    pub fn clear(&self) {
        if let Ok(mut s) = self.seen.lock() {
            *s = Seen::default();
        }
    }

    /// Every exchange seen on both sides since the last [`Self::clear`].
    pub fn legs(&self) -> Vec<Legs> {
        let Ok(seen) = self.seen.lock() else {
            return Vec::new();
        };
        seen.replies
            .iter()
            .filter_map(|&(t1, t2, t3, after_read)| {
                Some(Legs {
                    t1_ns: t1,
                    t2_ns: t2,
                    t3_ns: t3,
                    request_read_ns: *seen.request_read.get(&t1)?,
                    before_write_ns: *seen.written.get(&t1)?,
                    after_read_ns: after_read,
                    reply_written_ns: *seen.reply_written.get(&t1)?,
                })
            })
            .collect()
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
    link: Arc<Mutex<Link>>,
    seen: Arc<Mutex<Seen>>,
    stop: Arc<AtomicBool>,
}

/// Frames in one direction's byte stream, each with the instant of the chunk that held its
/// first byte.
struct Starts<const N: usize> {
    deframer: Deframer<N>,
    started: Option<Instant>,
}

impl<const N: usize> Starts<N> {
    fn new() -> Self {
        Self {
            deframer: Deframer::new(),
            started: None,
        }
    }

    /// Feeds `bytes` (a chunk met at `at`); calls `on_frame` with every frame completed and
    /// the instant its first byte was met.
    fn push(&mut self, bytes: &[u8], at: Instant, mut on_frame: impl FnMut(&mut [u8], Instant)) {
        for &b in bytes {
            if b != 0 && self.started.is_none() {
                self.started = Some(at);
            }
            match self.deframer.push(b) {
                Pushed::Frame(f) => on_frame(f, self.started.take().unwrap_or(at)),
                _ if b == 0 => self.started = None,
                _ => {}
            }
        }
    }
}

impl Ctx {
    fn ns(&self, at: Instant) -> i64 {
        at.saturating_duration_since(self.epoch).as_nanos() as i64
    }

    fn note(&self, f: impl FnOnce(&mut Seen)) {
        if let Ok(mut s) = self.seen.lock() {
            f(&mut s);
        }
    }

    /// Notes the clock-sync frames of a chunk met at `at` (read or about to be written).
    fn note_chunk(
        &self,
        (host, device): (&mut Starts<HOST_FRAME_MAX>, &mut Starts<DEVICE_FRAME_MAX>),
        bytes: &[u8],
        (at, written): (Instant, bool),
    ) {
        if self.forward {
            host.push(bytes, at, |f, first| {
                if let Ok(HostMsg::TimeSync(r)) = frame::decode::<HostMsg>(f).map(|p| p.msg) {
                    let first = self.ns(first);
                    self.note(|s| {
                        let map = if written {
                            &mut s.written
                        } else {
                            &mut s.request_read
                        };
                        map.insert(r.t1_ns, first);
                    });
                }
            });
        } else {
            device.push(bytes, at, |f, first| {
                if let Ok(DeviceMsg::TimeSync(r)) = frame::decode::<DeviceMsg>(f).map(|p| p.msg) {
                    let first = self.ns(first);
                    self.note(|s| {
                        if written {
                            s.reply_written.insert(r.t1_ns, first);
                        } else {
                            s.replies.push((r.t1_ns, r.t2_ns, r.t3_ns, first));
                        }
                    });
                }
            });
        }
    }

    /// Reads chunks, noting clock-sync frames at the read; each chunk is queued with its
    /// release time (never before the previous chunk's).
    fn read(&self, mut src: TTYPort, tx: &mpsc::Sender<(Instant, Vec<u8>)>) {
        let (mut host, mut device) = (Starts::new(), Starts::new());
        let mut buf = [0u8; 4096];
        let mut last_release = Instant::now();
        while !self.stop.load(Ordering::Relaxed) {
            let n = match src.read(&mut buf) {
                Ok(n) if n > 0 => n,
                _ => continue,
            };
            let after_read = Instant::now();
            self.note_chunk((&mut host, &mut device), &buf[..n], (after_read, false));
            let delay = self
                .link
                .lock()
                .map_or(Duration::ZERO, |mut l| l.draw(self.forward));
            last_release = last_release.max(after_read + delay);
            if tx.send((last_release, buf[..n].to_vec())).is_err() {
                return;
            }
        }
    }

    /// Writes each chunk at its release time, then notes its clock-sync frames with the instant
    /// just before the write of the chunk holding their first byte: the device stamps a
    /// request's first byte after that (`before_write`).
    fn write(&self, mut dst: TTYPort, rx: &mpsc::Receiver<(Instant, Vec<u8>)>) {
        let (mut host, mut device) = (Starts::new(), Starts::new());
        while !self.stop.load(Ordering::Relaxed) {
            let Ok((release, bytes)) = rx.recv_timeout(Duration::from_millis(20)) else {
                continue;
            };
            if self.forward {
                // Wake QEMU's threads for the chunk: a lone delimiter (an empty frame,
                // ignored), then the chunk WAKE_UP later at its release time.
                let wake_at = release.checked_sub(WAKE_UP).unwrap_or(release);
                let now = Instant::now();
                if wake_at > now {
                    std::thread::sleep(wake_at - now);
                }
                let _ = dst.write_all(&[0]);
                while Instant::now() < release {
                    std::hint::spin_loop();
                }
            }
            let now = Instant::now();
            if release > now {
                std::thread::sleep(release - now);
            }
            let before_write = Instant::now();
            let _ = dst.write_all(&bytes);
            self.note_chunk((&mut host, &mut device), &bytes, (before_write, true));
        }
    }
}
