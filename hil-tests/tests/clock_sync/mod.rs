//! HIL of the clock sync (issue 35, item 3): the link firmware's device clock (SysTick,
//! receive stamps in the UART interrupt) estimated by `msreg_host::link::clock_sync` through
//! a link with injected delay and jitter ([`msreg_hil_tests::jitter`]), against the truth
//! bracketed on the QEMU side of the injected delays.
//!
//! The host clock is the test's own: `Instant` run 50 ppm slow with an epoch near 2023 in
//! Unix ns, so the estimator must find a large offset and a 50 ppm skew; the device clock
//! counts from its boot.

use std::time::{Duration, Instant};

use msreg_hil_tests::jitter::{Delay, JitterProxy, Shape, TruthBracket};
use msreg_host::link::clock_sync::{ClockFit, ClockSync, ClockSyncOptions, Exchange};
use msreg_host::link::{Client, ClientOptions};
use msreg_protocol::TimeBase;

use crate::common::boot;

/// Host clock rate minus the true rate.
const HOST_SKEW: f64 = -50e-6;
/// Host clock at the proxy's epoch, ns.
const HOST_EPOCH_NS: i64 = 1_700_000_000_000_000_000;
/// The acceptance bound, ns.
const MAX_ERROR_NS: f64 = 100_000.0;
/// Exchanges per second and length of a phase; the error counts after `SETTLE_S`.
const RATE_HZ: f64 = 25.0;
const PHASE_S: f64 = 10.0;
const SETTLE_S: f64 = 4.0;

fn host_ns(epoch: Instant, at: Instant) -> i64 {
    let since = at.saturating_duration_since(epoch).as_nanos() as f64;
    HOST_EPOCH_NS + (since * (1.0 + HOST_SKEW)).round() as i64
}

/// What one phase measured.
#[derive(Debug)]
struct PhaseResult {
    /// Exchanges answered / sent.
    answered: usize,
    sent: usize,
    /// Error of the mapping against the bracket's middle at every answered exchange after
    /// the settling time: mean |.| and max |.|, ns.
    mean_ns: f64,
    max_ns: f64,
    /// Largest error the bracket allows (its far end), ns.
    max_bound_ns: f64,
    truth: TruthBracket,
    fit: ClockFit,
}

fn delay(floor_ms: f64, jitter_ms: f64) -> Delay {
    Delay {
        floor: Duration::from_secs_f64(floor_ms * 1e-3),
        jitter: Duration::from_secs_f64(jitter_ms * 1e-3),
        spike_p: 0.02,
    }
}

/// Runs `PHASE_S` of exchanges through `shape`; the estimator knows `asymmetry_ns`.
fn phase(client: &mut Client, proxy: &JitterProxy, shape: Shape, asymmetry_ns: i64) -> PhaseResult {
    proxy.set_shape(shape);
    std::thread::sleep(Duration::from_millis(100));
    proxy.clear();
    let mut sync = ClockSync::new(ClockSyncOptions {
        asymmetry_ns,
        ..ClockSyncOptions::default()
    });
    let start = Instant::now();
    let (mut sent, mut estimates) = (0, Vec::new());
    let mut fit = None;
    while start.elapsed().as_secs_f64() < PHASE_S {
        let slot = start + Duration::from_secs_f64(sent as f64 / RATE_HZ);
        if let Some(wait) = slot.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        sent += 1;
        let Some(x) = client.time_sync(Duration::from_millis(200)).expect("link") else {
            continue;
        };
        assert_eq!(x.reply.time_base, TimeBase::HostStamps);
        let e = Exchange {
            t1_ns: host_ns(proxy.epoch, x.sent),
            t2_ns: x.reply.t2_ns as i64,
            t3_ns: x.reply.t3_ns as i64,
            t4_ns: host_ns(proxy.epoch, x.received),
        };
        let f = sync.add(e).expect("causal exchange");
        if x.sent.duration_since(start).as_secs_f64() >= SETTLE_S {
            // The estimate of the device clock at the reply's arrival, against `Instant`.
            let at = x.received.duration_since(proxy.epoch).as_nanos() as i64;
            estimates.push(f.to_device(e.t4_ns) - at);
        }
        fit = Some(f);
    }
    let truth = proxy.truth();
    let mid = 0.5 * (truth.lower_ns as f64 + truth.upper_ns as f64);
    let errors: Vec<f64> = estimates.iter().map(|&c| c as f64 - mid).collect();
    let far: f64 = estimates
        .iter()
        .map(|&c| ((c - truth.lower_ns).abs()).max((c - truth.upper_ns).abs()) as f64)
        .fold(0.0, f64::max);
    PhaseResult {
        answered: sync.len(),
        sent,
        mean_ns: errors.iter().map(|e| e.abs()).sum::<f64>() / errors.len().max(1) as f64,
        max_ns: errors.iter().fold(0.0, |m, e| m.max(e.abs())),
        max_bound_ns: far,
        truth,
        fit: fit.expect("exchanges answered"),
    }
}

fn report(name: &str, r: &PhaseResult) {
    println!(
        "clock sync, {name}: {}/{} exchanges answered; error vs truth mid mean {:.1} us, max {:.1} us, max within the bracket {:.1} us; truth bracket {:.1} us wide from {} exchanges; fit skew {:.2} ppm +- {:.2}, sigma {:.1} us, asymmetry bound {:.0} us",
        r.answered,
        r.sent,
        r.mean_ns * 1e-3,
        r.max_ns * 1e-3,
        r.max_bound_ns * 1e-3,
        (r.truth.upper_ns - r.truth.lower_ns) as f64 * 1e-3,
        r.truth.exchanges,
        r.fit.skew * 1e6,
        r.fit.sigma_skew * 1e6,
        r.fit.sigma_ns * 1e-3,
        r.fit.asymmetry_bound_ns * 1e-3,
    );
}

fn check(name: &str, r: &PhaseResult) {
    report(name, r);
    // The truth is consistent (QEMU's virtual clock is the host's monotonic clock plus a
    // constant: one C satisfies every exchange) and tight enough to judge 0.1 ms
    assert!(
        r.truth.lower_ns <= r.truth.upper_ns,
        "{name}: {:?}",
        r.truth
    );
    assert!(r.truth.exchanges >= 100, "{name}: {:?}", r.truth);
    assert!(
        ((r.truth.upper_ns - r.truth.lower_ns) as f64) < MAX_ERROR_NS,
        "{name}: truth bracket too wide to judge: {:?}",
        r.truth
    );
    // most exchanges were answered (the spikes stay under the 200 ms wait)
    assert!(
        r.answered * 10 >= r.sent * 9,
        "{name}: {}/{}",
        r.answered,
        r.sent
    );
    // the mapping is within 0.1 ms of every clock the truth allows
    assert!(r.max_bound_ns < MAX_ERROR_NS, "{name}: {r:?}");
    // and the skew is the host clock's 50 ppm (device / host rate - 1), within 3 ppm
    let true_skew = 1.0 / (1.0 + HOST_SKEW) - 1.0;
    assert!(r.fit.skew_fitted);
    assert!((r.fit.skew - true_skew).abs() < 3e-6, "{name}: {:?}", r.fit);
    // and the reported uncertainty is finite and the asymmetry bound covers the error
    assert!(
        r.fit.sigma_ns.is_finite() && r.fit.sigma_skew.is_finite(),
        "{:?}",
        r.fit
    );
    assert!(r.max_ns <= r.fit.asymmetry_bound_ns, "{name}: {r:?}");
}

#[test]
#[ignore = "acceptance not met yet: 0.14-0.18 ms error vs 0.1 ms (docs/protocol.md, Clock sync); run with --ignored"]
fn clock_sync_error_under_injected_delay_and_jitter_is_below_a_tenth_of_a_millisecond() {
    // Given the link firmware behind a link that adds 2 ms floors, 2 ms of uniform jitter
    // out and 0.5 ms back, 2 % spikes of 1-10x the jitter each way
    let qemu = boot();
    let symmetric = Shape {
        forward: delay(2.0, 2.0),
        backward: delay(2.0, 0.5),
    };
    let proxy = JitterProxy::start(&qemu.pty, symmetric, 35).expect("proxy");
    let mut client = Client::connect(&proxy.path, ClientOptions::default(), None).expect("port");
    client
        .handshake(Duration::from_secs(10))
        .expect("handshake");
    let started = Instant::now();
    // When the host runs 25 exchanges a second for 10 s
    let a = phase(&mut client, &proxy, symmetric, 0);
    // Then the mapping is within 0.1 ms of the truth
    check("equal floors", &a);
    // Given floors of 3 ms out and 1 ms back, known to the host (as a UART's frame lengths)
    let asymmetric = Shape {
        forward: delay(3.0, 2.0),
        backward: delay(1.0, 0.5),
    };
    let b = phase(&mut client, &proxy, asymmetric, 2_000_000);
    // Then too
    check("3 ms / 1 ms floors, asymmetry known", &b);
    println!(
        "clock sync HIL: {:.1} s of exchanges; device errors reported: {:?}",
        started.elapsed().as_secs_f64(),
        client.collected.errors
    );
}
