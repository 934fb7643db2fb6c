//! Each stream's span, rate and gaps, and its time overlap with the IMU.

use super::findings::Span;
use super::sensors::SensorData;
use super::Finding;

/// An interval longer than this many median intervals is a gap.
pub const GAP_FACTOR: f64 = 3.0;
/// A stream sharing less than this fraction of its time with the IMU is warned about.
pub const MIN_OVERLAP_FRACTION: f64 = 0.9;

/// Rates, gaps and overlaps.
pub fn check(data: &SensorData) -> Vec<Finding> {
    let pose_stamps = data.pose0_stamps();
    let streams: Vec<(&str, &[u64])> = [
        ("imu0", data.imu_stamps.as_deref()),
        ("pose0", pose_stamps.as_deref()),
        ("cam0", data.cam0_stamps.as_deref()),
        ("lidar0", data.lidar0_stamps.as_deref()),
    ]
    .into_iter()
    .filter_map(|(name, stamps)| Some((name, stamps?)))
    .filter(|(_, stamps)| !stamps.is_empty())
    .collect();
    let mut findings = Vec::new();
    for (name, stamps) in &streams {
        findings.extend(rate_and_gaps(name, stamps));
    }
    let Some(imu) = data.imu_stamps.as_deref().filter(|s| !s.is_empty()) else {
        return findings;
    };
    let imu = span(imu);
    for (name, stamps) in streams.iter().filter(|(n, _)| *n != "imu0") {
        findings.extend(overlap(name, imu, span(stamps)));
    }
    findings
}

/// The span of non-empty stamps, s.
pub fn span(stamps: &[u64]) -> Span {
    Span {
        start_s: seconds(stamps[0]),
        end_s: seconds(stamps[stamps.len() - 1]),
    }
}

/// A stamp in seconds.
pub fn seconds(stamp_ns: u64) -> f64 {
    stamp_ns as f64 * 1e-9
}

fn rate_and_gaps(stream: &str, stamps: &[u64]) -> Vec<Finding> {
    let intervals: Vec<f64> = stamps
        .windows(2)
        .map(|w| (w[1] - w[0]) as f64 * 1e-9)
        .collect();
    let mut sorted = intervals.clone();
    sorted.sort_by(f64::total_cmp);
    let Some(&nominal) = sorted.get(sorted.len() / 2) else {
        return Vec::new();
    };
    let mut findings = vec![Finding::Rate {
        stream: stream.to_string(),
        samples: stamps.len(),
        span: span(stamps),
        rate_hz: 1.0 / nominal,
    }];
    let gaps: Vec<(usize, f64)> = intervals
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, dt)| *dt > GAP_FACTOR * nominal)
        .collect();
    if let Some(&(at, longest)) = gaps.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
        findings.push(Finding::Gaps {
            stream: stream.to_string(),
            count: gaps.len(),
            longest_s: longest,
            at_s: (stamps[at] - stamps[0]) as f64 * 1e-9,
            nominal_s: nominal,
        });
    }
    findings
}

fn overlap(stream: &str, imu: Span, other: Span) -> Option<Finding> {
    let shared = imu.end_s.min(other.end_s) - imu.start_s.max(other.start_s);
    if shared <= 0.0 {
        return Some(Finding::NoOverlap {
            stream: stream.to_string(),
            imu,
            other,
        });
    }
    (shared < MIN_OVERLAP_FRACTION * other.duration_s()).then(|| Finding::PartialOverlap {
        stream: stream.to_string(),
        overlap_s: shared,
        duration_s: other.duration_s(),
    })
}
