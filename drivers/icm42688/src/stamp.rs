//! Data-ready time stamps on the device (MCU) clock.
//!
//! The ICM-42688-P pulses INT1 each time a sample enters its FIFO (`UI_DRDY_INT1_EN`,
//! one packet per ODR period). The board's interrupt handler reads a monotonic clock and
//! counts the pulses: [`DataReady`] `{ stamp_ns, count }` is the time and number of the
//! latest pulse. [`crate::Icm42688::read_fifo`] takes a function that returns a copy of it
//! (read atomically, e.g. in a critical section) and calls it twice: before it reads
//! `FIFO_COUNT` and after the burst.
//!
//! Packets are numbered from the FIFO's start. The packet of pulse `n` is `n + offset`.
//! When no pulse came during the read (both copies equal), the FIFO's newest packet is the
//! latest pulse's: that fixes `offset` at the first burst and checks it at every later one.
//! Each packet `p` is stamped `stamp_ns + (p - (count + offset)) * period` with the first
//! copy: packets that queued while the main loop was busy get earlier stamps, one that
//! landed between the first copy and the count read a stamp one period later.
//!
//! Assumptions (each checked where it can be):
//! - one packet per pulse: INT1 pulsed (100 us) at the ODR and every pulse counted. A
//!   missed pulse (interrupts masked for more than a period), a FIFO overflow or a flush
//!   breaks the count; the next quiet burst finds its newest packet off the pulse count
//!   and re-anchors (counted in [`Stamper::resyncs`]);
//! - the interrupt runs within the burst's duration of the pulse (true unless it is masked
//!   or pre-empted for tens of microseconds), so the second copy has counted every packet
//!   the burst read;
//! - the handler's latency is constant: its jitter goes into the stamps as is;
//! - the period is the IMU oscillator's, tracked on the device clock: each copy measures
//!   `(stamp - previous stamp) / (count - previous count)` and the estimate follows it with
//!   a time constant of [`PERIOD_SMOOTHING`] samples; a measurement more than
//!   [`PERIOD_TOLERANCE`] from the nominal ODR period is ignored (a glitch, not drift);
//! - a (re-)anchoring burst during which a pulse came is ambiguous by one packet: its
//!   stamps use the first copy as if no packet had landed, and the next quiet burst
//!   anchors (counted in [`Stamper::resyncs`] when it moves the map);
//! - stamps strictly increase: a stamp not after the previous one is moved 1 ns after it
//!   (counted in [`Stamper::clamped`]); the estimator refuses time going backwards.

/// Time and number of the latest data-ready pulse, taken in its interrupt handler.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct DataReady {
    /// Monotonic clock at the pulse, ns.
    pub stamp_ns: u64,
    /// Pulses since the handler started counting (wraps).
    pub count: u32,
}

/// Samples over which the period estimate follows a measurement.
pub const PERIOD_SMOOTHING: f32 = 64.0;
/// Largest accepted deviation of a measured period from the nominal one (fraction).
pub const PERIOD_TOLERANCE: f32 = 0.1;

/// Assigns stamps to FIFO packets from the data-ready pulses (module docs).
#[derive(Clone, Debug)]
pub struct Stamper {
    nominal_ns: f32,
    period_ns: f32,
    /// Pulses counted so far, unwrapped, and the last [`DataReady`] seen.
    pulses: u64,
    last: Option<DataReady>,
    /// Packet number minus pulse number; `None` until the first burst or after a resync.
    offset: Option<i64>,
    /// Number of the next packet to be read.
    next_packet: u64,
    last_stamp: Option<u64>,
    resyncs: u32,
    clamped: u32,
}

impl Stamper {
    /// A stamper for a nominal ODR period.
    pub fn new(nominal_period_ns: u32) -> Self {
        let nominal_ns = nominal_period_ns as f32;
        Self {
            nominal_ns,
            period_ns: nominal_ns,
            pulses: 0,
            last: None,
            offset: None,
            next_packet: 0,
            last_stamp: None,
            resyncs: 0,
            clamped: 0,
        }
    }

    /// The period estimate, ns.
    pub fn period_ns(&self) -> f32 {
        self.period_ns
    }

    /// Times the packet-to-pulse map was re-anchored after the first burst.
    pub fn resyncs(&self) -> u32 {
        self.resyncs
    }

    /// Stamps moved forward to keep them increasing.
    pub fn clamped(&self) -> u32 {
        self.clamped
    }

    /// Forget the packet-to-pulse map (the FIFO was flushed): the next burst re-anchors.
    pub fn flush(&mut self) {
        if self.offset.take().is_some() {
            self.resyncs = self.resyncs.saturating_add(1);
        }
    }

    /// Counts the pulses up to `drdy` and measures the period since the previous copy;
    /// returns the unwrapped pulse number.
    fn observe(&mut self, drdy: DataReady) -> i64 {
        if let Some(last) = self.last {
            let dc = drdy.count.wrapping_sub(last.count);
            self.pulses += u64::from(dc);
            let dt = drdy.stamp_ns.saturating_sub(last.stamp_ns);
            if dc > 0 && dt > 0 {
                let measured = dt as f32 / dc as f32;
                if (measured - self.nominal_ns).abs() <= PERIOD_TOLERANCE * self.nominal_ns {
                    let gain = dc as f32 / (dc as f32 + PERIOD_SMOOTHING);
                    self.period_ns += gain * (measured - self.period_ns);
                }
            }
        }
        self.last = Some(drdy);
        self.pulses as i64
    }

    /// Starts a burst of `fifo_packets` whole packets: `before` and `after` are the copies
    /// of the latest pulse taken before the FIFO count read and after the burst. Returns
    /// the number of the packet of `before`'s pulse (module docs).
    pub fn begin_burst(&mut self, before: DataReady, after: DataReady, fifo_packets: u32) -> i64 {
        let pulse_before = self.observe(before);
        let pulse_after = self.observe(after);
        let newest = self.next_packet as i64 + i64::from(fifo_packets) - 1;
        let quiet = pulse_after == pulse_before;
        if let Some(o) = self.offset {
            let lead = newest - (pulse_before + o);
            let consistent = if quiet {
                lead == 0
            } else {
                (0..=pulse_after - pulse_before).contains(&lead)
            };
            if consistent {
                return pulse_before + o;
            }
            self.resyncs = self.resyncs.saturating_add(1);
        }
        self.offset = quiet.then_some(newest - pulse_before);
        newest
    }

    /// The stamp of the next packet (number `next_packet`), given the packet `anchor` of
    /// [`Stamper::begin_burst`] and its pulse; advances to the following packet.
    pub fn next_stamp(&mut self, drdy: DataReady, anchor: i64) -> u64 {
        let p = self.next_packet as i64;
        self.next_packet += 1;
        let delta = ((p - anchor) as f32 * self.period_ns) as i64;
        let mut stamp = if delta >= 0 {
            drdy.stamp_ns.saturating_add(delta as u64)
        } else {
            drdy.stamp_ns.saturating_sub(delta.unsigned_abs())
        };
        if let Some(last) = self.last_stamp {
            if stamp <= last {
                stamp = last + 1;
                self.clamped = self.clamped.saturating_add(1);
            }
        }
        self.last_stamp = Some(stamp);
        stamp
    }
}
