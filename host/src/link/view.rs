//! The live view of `msreg link monitor` (and of `replay` on a terminal): a full screen
//! redrawn in place with ANSI escapes when stdout is a terminal, one plain line per new
//! estimate, alarm or fault otherwise (pipes, files, tests).
//!
//! Plain ANSI (cursor home, clear to end of line / screen, colours) is all a dashboard of
//! fixed rows needs, so no terminal library is pulled in. The screen is not switched to the
//! alternate buffer: after Ctrl-C the last state stays readable in the terminal.

use std::collections::{BTreeMap, VecDeque};
use std::io::IsTerminal;

use msreg_protocol::{
    AlarmKind, ErrorKind, Estimate, HealthState, NisState, Status, UpdateDiagnostic, UpdateKind,
};
use nalgebra::{Quaternion, UnitQuaternion};

use super::client::Collected;

/// How the view is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Full screen, redrawn in place (a terminal).
    Screen,
    /// One line per event (not a terminal).
    Lines,
}

impl Mode {
    /// `Screen` when stdout is a terminal that understands ANSI, else `Lines`.
    pub fn detect() -> Self {
        let dumb = std::env::var("TERM").is_ok_and(|t| t == "dumb");
        if std::io::stdout().is_terminal() && !dumb {
            Mode::Screen
        } else {
            Mode::Lines
        }
    }
}

/// Most screen redraws per second (a person cannot read faster; the link is not slowed).
const REDRAWS_PER_S: f64 = 5.0;
/// Window of the link-rate figure, s.
const RATE_WINDOW_S: f64 = 2.0;

const HOME: &str = "\x1b[H";
const CLEAR_LINE: &str = "\x1b[K";
const CLEAR_BELOW: &str = "\x1b[J";
const CLEAR_SCREEN: &str = "\x1b[2J";
const BOLD: &str = "\x1b[1m";
const RED: &str = "\x1b[1;37;41m";
const GREEN: &str = "\x1b[1;32m";
const YELLOW: &str = "\x1b[1;33m";
const DIM: &str = "\x1b[2m";
const RESET: &str = "\x1b[0m";

/// The live view's state between draws.
pub struct LiveView {
    mode: Mode,
    title: String,
    last_draw_s: Option<f64>,
    /// Events already printed in line mode.
    shown: usize,
    /// (host time, messages received so far), for the link rate.
    history: VecDeque<(f64, u64)>,
}

impl LiveView {
    /// A view titled `title` (e.g. the port).
    pub fn new(mode: Mode, title: &str) -> Self {
        Self {
            mode,
            title: title.to_string(),
            last_draw_s: None,
            shown: 0,
            history: VecDeque::new(),
        }
    }

    /// What to write to stdout now, if anything.
    pub fn frame(&mut self, c: &Collected, now_s: f64) -> Option<String> {
        let received = messages_received(c);
        self.history.push_back((now_s, received));
        while self
            .history
            .front()
            .is_some_and(|(t, _)| now_s - t > RATE_WINDOW_S)
        {
            self.history.pop_front();
        }
        match self.mode {
            Mode::Lines => {
                let events = c.estimates.len() + c.alarms.len() + c.errors.len();
                if events == self.shown {
                    return None;
                }
                self.shown = events;
                Some(format!("{}\n", live_view(c)))
            }
            Mode::Screen => {
                if self
                    .last_draw_s
                    .is_some_and(|t| now_s - t < 1.0 / REDRAWS_PER_S)
                {
                    return None;
                }
                let first = self.last_draw_s.is_none();
                self.last_draw_s = Some(now_s);
                let mut out = String::new();
                if first {
                    out.push_str(CLEAR_SCREEN);
                }
                out.push_str(HOME);
                for line in dashboard(c, &self.title, now_s, self.rate(), true) {
                    out.push_str(&line);
                    out.push_str(CLEAR_LINE);
                    out.push('\n');
                }
                out.push_str(CLEAR_BELOW);
                Some(out)
            }
        }
    }

    /// Messages per second received over the last [`RATE_WINDOW_S`].
    fn rate(&self) -> f64 {
        match (self.history.front(), self.history.back()) {
            (Some((t0, n0)), Some((t1, n1))) if t1 > t0 => (n1 - n0) as f64 / (t1 - t0),
            _ => 0.0,
        }
    }
}

/// Every device message the client decoded (acks included).
fn messages_received(c: &Collected) -> u64 {
    (c.estimates.len() + c.diagnostics.len() + c.alarms.len() + c.errors.len()) as u64
        + c.acks.iter().sum::<u64>()
        + u64::from(c.hello.is_some())
}

fn paint(color: bool, code: &str, text: &str) -> String {
    if color {
        format!("{code}{text}{RESET}")
    } else {
        text.to_string()
    }
}

/// Roll, pitch, yaw of the estimated extrinsic rotation, degrees.
pub fn rpy_deg(e: &Estimate) -> [f64; 3] {
    let [w, x, y, z] = e.extrinsic.rotation_wxyz.map(f64::from);
    let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
    let (r, p, yaw) = q.euler_angles();
    [r.to_degrees(), p.to_degrees(), yaw.to_degrees()]
}

/// Latest running count per fault kind, from the device's error reports.
pub fn fault_counts(c: &Collected) -> BTreeMap<usize, (ErrorKind, u32)> {
    let mut counts = BTreeMap::new();
    for (_, e) in &c.errors {
        let entry = counts.entry(e.kind.index()).or_insert((e.kind, 0));
        entry.1 = entry.1.max(e.count);
    }
    counts
}

fn health_badge(e: Option<&Estimate>, color: bool) -> String {
    match e.map(|e| e.health) {
        Some(HealthState::Alarm) => paint(color, RED, " ALARM "),
        Some(HealthState::Nominal) => paint(color, GREEN, "NOMINAL"),
        Some(HealthState::Idle) | None => paint(color, DIM, "waiting"),
    }
}

fn nis_text(e: &Estimate, color: bool) -> String {
    let (word, code) = match e.nis_state {
        NisState::Filling => ("filling window", DIM),
        NisState::Consistent => ("consistent", GREEN),
        NisState::High => ("HIGH: over-confident or mis-modelled", YELLOW),
        NisState::Low => ("low: noise set too large", YELLOW),
    };
    format!("{:.2} ({})", e.nis_per_dof, paint(color, code, word))
}

/// The earliest device stamp of the session: filter times are shown from it (device stamps
/// are the sensor clock's, often seconds since 1970).
fn origin_ns(c: &Collected) -> u64 {
    let first_estimate = c.estimates.first().map(|(_, e)| e.stamp_ns);
    let first_update = c.diagnostics.first().map(|(_, d)| d.stamp_ns);
    first_estimate
        .into_iter()
        .chain(first_update)
        .min()
        .unwrap_or(0)
}

fn since(stamp_ns: u64, origin_ns: u64) -> f64 {
    stamp_ns.saturating_sub(origin_ns) as f64 * 1e-9
}

fn diagnostic_text(d: &UpdateDiagnostic, origin_ns: u64) -> String {
    let kind = match d.kind {
        UpdateKind::RelativePose => "relative pose",
        UpdateKind::ZeroVelocity => "zero velocity",
        UpdateKind::Reprojection => "reprojection",
        UpdateKind::BoardPlane => "board plane",
    };
    format!(
        "{kind} at t+{:.2} s: NIS {:.2} vs gate {:.2} ({} dof), {}",
        since(d.stamp_ns, origin_ns),
        d.nis,
        d.threshold,
        d.dof,
        if d.accepted { "accepted" } else { "REJECTED" }
    )
}

/// The full-screen dashboard, one string per row (no trailing newline, ANSI colours when
/// `color`).
pub fn dashboard(
    c: &Collected,
    title: &str,
    now_s: f64,
    rx_per_s: f64,
    color: bool,
) -> Vec<String> {
    let mut rows = Vec::new();
    let version = c.hello.map_or("?".to_string(), |h| h.version.to_string());
    rows.push(paint(
        color,
        BOLD,
        &format!("msreg link  {title}  protocol v{version}  session {now_s:.1} s"),
    ));
    rows.push("-".repeat(72));
    let last = c.estimates.last().map(|(_, e)| e);
    let alarms = last.map_or(c.alarms.len() as u32, |e| u32::from(e.alarms));
    rows.push(format!(
        "HEALTH  {}   alarms {}",
        health_badge(last, color),
        alarms
    ));
    let Some(e) = last else {
        rows.push(String::new());
        rows.push(
            "waiting for the first estimate (the device sends one per update or period)".into(),
        );
        push_link_rows(&mut rows, c, rx_per_s, color);
        return rows;
    };
    let origin = origin_ns(c);
    rows.push(format!(
        "NIS/dof {}   updates {} accepted, {} rejected   filter time t+{:.2} s",
        nis_text(e, color),
        e.updates_accepted,
        e.updates_rejected,
        since(e.stamp_ns, origin)
    ));
    rows.push(String::new());
    rows.push(paint(
        color,
        BOLD,
        &format!(
            "{:<24}{:>12}{:>12}",
            format!("extrinsic T_imu_sensor{}", e.sensor),
            "estimate",
            "1 sigma"
        ),
    ));
    let r = rpy_deg(e);
    for (i, name) in ["roll  [deg]", "pitch [deg]", "yaw   [deg]"]
        .iter()
        .enumerate()
    {
        rows.push(format!(
            "  {name:<22}{:>12.3}{:>12.3}",
            r[i],
            f64::from(e.sigma_rotation_rad[i]).to_degrees()
        ));
    }
    for (i, name) in ["x     [m]", "y     [m]", "z     [m]"].iter().enumerate() {
        rows.push(format!(
            "  {name:<22}{:>12.4}{:>12.4}",
            e.extrinsic.translation_m[i], e.sigma_translation_m[i]
        ));
    }
    rows.push(format!(
        "  {:<22}{:>12.2}{:>12.2}",
        "time offset [ms]",
        e.time_offset_s * 1e3,
        e.sigma_time_offset_s * 1e3
    ));
    rows.push(String::new());
    rows.push(match c.diagnostics.last() {
        Some((_, d)) => format!("last update  {}", diagnostic_text(d, origin)),
        None => "last update  none yet".into(),
    });
    rows.push(match c.alarms.last() {
        Some((t, a)) => {
            let kind = match a.kind {
                AlarmKind::RotationStep => "rotation step",
                AlarmKind::TranslationStep => "translation step",
            };
            paint(
                color,
                YELLOW,
                &format!(
                    "last alarm   {kind} of sensor {} at t+{:.2} s (statistic {:.1}), host t {t:.1} s",
                    a.sensor,
                    since(a.stamp_ns, origin),
                    a.statistic
                ),
            )
        }
        None => "last alarm   none".into(),
    });
    push_link_rows(&mut rows, c, rx_per_s, color);
    rows
}

fn push_link_rows(rows: &mut Vec<String>, c: &Collected, rx_per_s: f64, color: bool) {
    let faults = fault_counts(c);
    let fault_text = if faults.is_empty() {
        paint(color, GREEN, "none")
    } else {
        let list: Vec<String> = faults
            .values()
            .map(|(k, n)| format!("{} {n}", k.name()))
            .collect();
        paint(color, YELLOW, &list.join(", "))
    };
    rows.push(format!("faults       {fault_text}"));
    rows.push(format!(
        "link         {rx_per_s:.0} msg/s in; {} estimates, {} diagnostics, acks {}/{}/{} (ok/dup/rejected), {} ack timeouts, {} bad frames",
        c.estimates.len(),
        c.diagnostics.len(),
        c.acks[0],
        c.acks[1],
        c.acks[2],
        c.ack_timeouts,
        c.bad_frames
    ));
}

/// A few lines a person can read at a glance: estimate, sigmas, NIS, health, faults.
pub fn live_view(c: &Collected) -> String {
    match c.estimates.last() {
        Some((t, e)) => estimate_line(c, *t, e),
        None => format!(
            "t {:>7.2} s | waiting for estimates | errors {}",
            c.errors.last().map_or(0.0, |x| x.0),
            c.errors.len()
        ),
    }
}

/// The last estimate of every sensor that sent one, a line each (one sensor: as
/// [`live_view`]).
pub fn final_estimates(c: &Collected) -> String {
    let mut sensors: Vec<u8> = c.estimates.iter().map(|(_, e)| e.sensor).collect();
    sensors.sort_unstable();
    sensors.dedup();
    if sensors.len() < 2 {
        return live_view(c);
    }
    sensors
        .iter()
        .filter_map(|s| c.estimates.iter().rev().find(|(_, e)| e.sensor == *s))
        .map(|(t, e)| format!("pose{}: {}", e.sensor, estimate_line(c, *t, e)))
        .collect::<Vec<_>>()
        .join("\n")
}

fn estimate_line(c: &Collected, t: f64, e: &msreg_protocol::Estimate) -> String {
    let mut out = String::new();
    let r = rpy_deg(e);
    let sr = e.sigma_rotation_rad.map(|s| f64::from(s).to_degrees());
    let health = match e.health {
        HealthState::Alarm => "ALARM",
        HealthState::Nominal => "ok",
        HealthState::Idle => "idle",
    };
    out.push_str(&format!(
        "t {t:>7.2} s | rpy {:>8.3} {:>8.3} {:>8.3} deg (+-{:.3} {:.3} {:.3}) | xyz {:>7.4} {:>7.4} {:>7.4} m (+-{:.4} {:.4} {:.4}) | td {:>6.2} ms (+-{:.2}) | NIS/dof {:.2} {:?} | health {health} ({} alarms) | upd {}/{} | errors {}",
        r[0], r[1], r[2], sr[0], sr[1], sr[2],
        e.extrinsic.translation_m[0], e.extrinsic.translation_m[1], e.extrinsic.translation_m[2],
        e.sigma_translation_m[0], e.sigma_translation_m[1], e.sigma_translation_m[2],
        e.time_offset_s * 1e3, e.sigma_time_offset_s * 1e3,
        e.nis_per_dof, e.nis_state, e.alarms,
        e.updates_accepted, e.updates_accepted + e.updates_rejected,
        c.errors.len(),
    ));
    out
}

fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// Multi-line summary of a session.
pub fn summary(c: &Collected, status: Option<&Status>) -> String {
    let mut out = String::new();
    out.push_str(&format!("{}\n", final_estimates(c)));
    out.push_str(&format!(
        "device: {} estimates, {} update diagnostics, {} alarms, {} error reports; acks ok/dup/rejected {}/{}/{}, ack timeouts {}, bad frames {}\n",
        c.estimates.len(), c.diagnostics.len(), c.alarms.len(), c.errors.len(),
        c.acks[0], c.acks[1], c.acks[2], c.ack_timeouts, c.bad_frames
    ));
    for (t, a) in &c.alarms {
        out.push_str(&format!(
            "alarm at host t {t:.2} s: {:?} of sensor {} at stamp {} ns, statistic {:.1}\n",
            a.kind, a.sensor, a.stamp_ns, a.statistic
        ));
    }
    if let Some(s) = status {
        out.push_str(&format!(
            "status: configured {}, {} frames, {} IMU samples, {} anchors, {} updates, {} zero-velocity\n",
            s.configured, s.frames_ok, s.imu_samples, s.anchors, s.updates, s.zero_velocity_updates
        ));
        let faults: Vec<String> = ErrorKind::ALL
            .iter()
            .filter(|k| s.errors[k.index()] > 0)
            .map(|k| format!("{} {}", k.name(), s.errors[k.index()]))
            .collect();
        out.push_str(&format!(
            "fault counters: {}\n",
            if faults.is_empty() {
                "none".to_string()
            } else {
                faults.join(", ")
            }
        ));
    }
    if !c.ack_latency_s.is_empty() {
        out.push_str(&format!(
            "ack round trip: median {:.2} ms, p95 {:.2} ms; estimate latency: median {:.2} ms, p95 {:.2} ms\n",
            percentile(&c.ack_latency_s, 0.5) * 1e3,
            percentile(&c.ack_latency_s, 0.95) * 1e3,
            percentile(&c.estimate_latency_s, 0.5) * 1e3,
            percentile(&c.estimate_latency_s, 0.95) * 1e3
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_protocol::{ErrorReport, HealthAlarm, Pose};

    fn estimate(health: HealthState) -> Estimate {
        Estimate {
            stamp_ns: 12_500_000_000,
            extrinsic: Pose {
                rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
                translation_m: [0.1, -0.05, 0.2],
            },
            sigma_rotation_rad: [0.01, 0.02, 0.03],
            sigma_translation_m: [0.004, 0.005, 0.006],
            time_offset_s: 0.01,
            sigma_time_offset_s: 0.001,
            nis_per_dof: 1.05,
            nis_state: NisState::Consistent,
            health,
            alarms: u16::from(health == HealthState::Alarm),
            updates_accepted: 120,
            updates_rejected: 3,
            last_seq: 9,
            sensor: 0,
        }
    }

    fn collected(health: HealthState) -> Collected {
        let mut c = Collected::default();
        c.estimates.push((1.0, estimate(health)));
        for count in 1..=3 {
            c.errors.push((
                1.0,
                ErrorReport {
                    kind: ErrorKind::Crc,
                    count,
                    seq: 0,
                    stamp_ns: 0,
                },
            ));
        }
        if health == HealthState::Alarm {
            c.alarms.push((
                2.0,
                HealthAlarm {
                    stamp_ns: 14_000_000_000,
                    kind: AlarmKind::RotationStep,
                    statistic: 45.0,
                    step: [0.0; 3],
                    sensor: 1,
                },
            ));
        }
        c
    }

    #[test]
    fn dashboard_shows_estimate_sigmas_health_and_faults() {
        let rows = dashboard(
            &collected(HealthState::Alarm),
            "/dev/pts/9",
            3.0,
            42.0,
            false,
        );
        let text = rows.join("\n");
        assert!(text.contains("ALARM"), "{text}");
        // Stamps from the first estimate's (12.5 s).
        assert!(
            text.contains("rotation step of sensor 1 at t+1.50 s"),
            "{text}"
        );
        assert!(text.contains("crc 3"), "{text}");
        assert!(text.contains("42 msg/s"), "{text}");
        assert!(text.contains("120 accepted, 3 rejected"), "{text}");
        // z translation and its sigma, time offset in ms.
        assert!(text.contains("0.2000") && text.contains("0.0060"), "{text}");
        assert!(text.contains("10.00"), "{text}");
        assert!(!text.contains('\x1b'));
        let ok = dashboard(&collected(HealthState::Nominal), "p", 3.0, 0.0, false).join("\n");
        assert!(ok.contains("NOMINAL") && !ok.contains("ALARM"), "{ok}");
    }

    #[test]
    fn screen_mode_redraws_in_place_and_line_mode_prints_plain_lines() {
        let c = collected(HealthState::Nominal);
        let mut screen = LiveView::new(Mode::Screen, "p");
        let first = screen.frame(&c, 0.0).expect("first draw");
        assert!(first.starts_with("\x1b[2J\x1b[H"));
        assert!(screen.frame(&c, 0.05).is_none(), "redraws are rate-limited");
        let again = screen.frame(&c, 0.5).expect("redraw");
        assert!(again.starts_with("\x1b[H") && again.ends_with("\x1b[J"));

        let mut lines = LiveView::new(Mode::Lines, "p");
        let line = lines.frame(&c, 0.0).expect("first line");
        assert!(!line.contains('\x1b') && line.ends_with('\n'));
        assert_eq!(line.matches('\n').count(), 1);
        assert!(
            lines.frame(&c, 1.0).is_none(),
            "nothing new, nothing printed"
        );
    }
}
