//! `sensor_msgs/PointCloud2` to the dataset's [`PointCloud`]: `x y z` (FLOAT32/FLOAT64),
//! `intensity`, `ring` (or `line`, `channel`) and the per-point time.
//!
//! Per-point time is read from the first field named `t`, `time`, `timestamp` or
//! `offset_time` (Ouster `t` uint32 ns, Velodyne `time` float32 s relative, Hesai /
//! Robosense `timestamp` float64 s absolute, Livox `timestamp` float64 ns absolute /
//! `offset_time` uint32 ns relative). Its unit and whether it is absolute or relative to
//! the header stamp are decided from the values: a unit (tried in the order s, ns, us for
//! float fields and ns, us, s for integer ones) under which the scan's times lie within an
//! hour of the header stamp, and nearer to it than to zero, makes them absolute; otherwise
//! they are offsets from the header stamp in the first unit of the order. The scan is then
//! stamped at its first firing, `min(header stamp, earliest point)`, and each point's `t`
//! is its offset from that stamp (docs/formats.md, `lidar0/<timestamp_ns>.pcd`).
//!
//! Points with a non-finite coordinate, or exactly at the origin (the "no return" marker of
//! organised clouds), are dropped.

use nalgebra::Vector3;

use super::error::DecodeError;
use super::msgs::{PointCloud2Msg, PointField};
use crate::pointcloud::{Point, PointCloud};

/// The per-point time field names looked for, in order.
pub const TIME_FIELDS: [&str; 4] = ["t", "time", "timestamp", "offset_time"];
/// The ring field names looked for, in order.
const RING_FIELDS: [&str; 3] = ["ring", "line", "channel"];
/// Absolute point times must lie this close to the header stamp (1 h).
const ABSOLUTE_WINDOW_NS: f64 = 3.6e12;
/// The widest per-point time span kept: larger spans mean a wrong unit guess (1 s).
pub const MAX_SPAN_NS: u64 = 1_000_000_000;

/// The unit of a per-point time field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum TimeUnit {
    /// Seconds.
    Seconds,
    /// Microseconds.
    Microseconds,
    /// Nanoseconds.
    Nanoseconds,
}

impl TimeUnit {
    fn ns(self) -> f64 {
        match self {
            TimeUnit::Seconds => 1e9,
            TimeUnit::Microseconds => 1e3,
            TimeUnit::Nanoseconds => 1.0,
        }
    }
}

/// How the per-point time of a scan was read.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub enum PointTime {
    /// No time field: every point gets `t = 0` (no deskewing possible).
    Missing,
    /// A time field, absolute (since the epoch) or relative to the header stamp.
    Field {
        /// Field name.
        name: String,
        /// Unit decided.
        unit: TimeUnit,
        /// Absolute stamps (true) or offsets from the header stamp (false).
        absolute: bool,
    },
}

/// One converted scan.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// First firing, ns (the PCD file name).
    pub stamp_ns: u64,
    /// The points, `t` relative to `stamp_ns`.
    pub cloud: PointCloud,
    /// How the time was read.
    pub time: PointTime,
    /// Largest per-point offset, ns (before any drop).
    pub span_ns: u64,
    /// The span exceeded [`MAX_SPAN_NS`] and the per-point times were set to zero.
    pub time_dropped: bool,
    /// `x y z` were FLOAT64 (write them as `F8` to stay exact).
    pub xyz_f64: bool,
}

/// A field's reader: byte offset, datatype, endianness.
#[derive(Debug, Clone, Copy)]
struct FieldReader {
    offset: usize,
    datatype: u8,
    big_endian: bool,
}

impl FieldReader {
    fn size(self) -> usize {
        match self.datatype {
            1 | 2 => 1,
            3 | 4 => 2,
            5..=7 => 4,
            _ => 8,
        }
    }

    /// The value in the point starting at `data`; `data` holds at least the point.
    fn read(self, data: &[u8]) -> f64 {
        let mut b = [0u8; 8];
        let n = self.size();
        b[..n].copy_from_slice(&data[self.offset..self.offset + n]);
        if self.big_endian {
            b[..n].reverse();
        }
        match self.datatype {
            1 => f64::from(b[0] as i8),
            2 => f64::from(b[0]),
            3 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            4 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            5 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            6 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            7 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            _ => f64::from_le_bytes(b),
        }
    }

    fn is_float(self) -> bool {
        self.datatype >= 7
    }
}

fn field(
    msg: &PointCloud2Msg<'_>,
    names: &[&str],
) -> Result<Option<(String, FieldReader)>, DecodeError> {
    let Some(f) = names
        .iter()
        .find_map(|n| msg.fields.iter().find(|f| f.name == *n))
    else {
        return Ok(None);
    };
    let reader = checked_reader(msg, f)?;
    Ok(Some((f.name.clone(), reader)))
}

fn checked_reader(msg: &PointCloud2Msg<'_>, f: &PointField) -> Result<FieldReader, DecodeError> {
    if !(1..=8).contains(&f.datatype) {
        return Err(DecodeError::PointFieldType {
            name: f.name.clone(),
            datatype: f.datatype,
        });
    }
    let reader = FieldReader {
        offset: f.offset as usize,
        datatype: f.datatype,
        big_endian: msg.is_bigendian,
    };
    let end = reader.offset + reader.size();
    if end > msg.point_step as usize {
        return Err(DecodeError::DataSize {
            len: msg.point_step as usize,
            need: end,
        });
    }
    Ok(reader)
}

/// Point records of the message (row by row), checked against the data length.
fn records<'a>(msg: &PointCloud2Msg<'a>) -> Result<Vec<&'a [u8]>, DecodeError> {
    let (h, w) = (msg.height as usize, msg.width as usize);
    let (step, row_step) = (msg.point_step as usize, msg.row_step as usize);
    if h == 0 || w == 0 {
        return Ok(Vec::new());
    }
    let need = (h - 1) * row_step + w * step;
    if msg.data.len() < need || step == 0 {
        return Err(DecodeError::DataSize {
            len: msg.data.len(),
            need,
        });
    }
    let mut out = Vec::with_capacity(h * w);
    for row in 0..h {
        for col in 0..w {
            let start = row * row_step + col * step;
            out.push(&msg.data[start..start + step]);
        }
    }
    Ok(out)
}

/// Converts a `PointCloud2` whose effective header stamp is `stamp_ns`.
pub fn convert_cloud(msg: &PointCloud2Msg<'_>, stamp_ns: u64) -> Result<Scan, DecodeError> {
    let xyz = [["x"], ["y"], ["z"]].map(|n| field(msg, &n));
    let [Ok(Some((_, x))), Ok(Some((_, y))), Ok(Some((_, z)))] = xyz else {
        return Err(DecodeError::NoXyz);
    };
    if !(x.is_float() && y.is_float() && z.is_float()) {
        return Err(DecodeError::NoXyz);
    }
    let intensity = field(msg, &["intensity"])?.map(|f| f.1);
    let ring = field(msg, &RING_FIELDS)?.map(|f| f.1);
    let time = field(msg, &TIME_FIELDS)?;
    let mut points = Vec::new();
    let mut raw_times = Vec::new();
    for rec in records(msg)? {
        let p = Vector3::new(x.read(rec), y.read(rec), z.read(rec));
        if !p.iter().all(|c| c.is_finite()) || p == Vector3::zeros() {
            continue;
        }
        points.push(Point {
            xyz: p,
            intensity: intensity.map_or(0.0, |f| f.read(rec) as f32),
            t_ns: 0,
            ring: ring.map_or(0, |f| f.read(rec).clamp(0.0, f64::from(u16::MAX)) as u16),
        });
        if let Some((_, t)) = time {
            raw_times.push(t.read(rec));
        }
    }
    let mut scan = Scan {
        stamp_ns,
        cloud: PointCloud::new(points),
        time: PointTime::Missing,
        span_ns: 0,
        time_dropped: false,
        xyz_f64: x.datatype == 8,
    };
    if let Some((name, reader)) = time {
        apply_times(&mut scan, name, reader.is_float(), &raw_times);
    }
    Ok(scan)
}

/// Decides unit and mode, restamps the scan at its first firing and fills `t`.
fn apply_times(scan: &mut Scan, name: String, float: bool, raw: &[f64]) {
    let finite = || raw.iter().copied().filter(|v| v.is_finite());
    let (Some(lo), Some(hi)) = (
        finite().min_by(f64::total_cmp),
        finite().max_by(f64::total_cmp),
    ) else {
        return;
    };
    let order = if float {
        [
            TimeUnit::Seconds,
            TimeUnit::Nanoseconds,
            TimeUnit::Microseconds,
        ]
    } else {
        [
            TimeUnit::Nanoseconds,
            TimeUnit::Microseconds,
            TimeUnit::Seconds,
        ]
    };
    let header = scan.stamp_ns as f64;
    let mid = 0.5 * (lo + hi);
    let absolute_unit = order.iter().copied().find(|u| {
        let v = mid * u.ns();
        (v - header).abs() < ABSOLUTE_WINDOW_NS && (v - header).abs() < v.abs()
    });
    let (unit, absolute) = absolute_unit.map_or((order[0], false), |u| (u, true));
    let to_ns = |v: f64| -> i128 {
        let ns = (v * unit.ns()).round() as i128;
        if absolute {
            ns
        } else {
            i128::from(scan.stamp_ns) + ns
        }
    };
    let abs: Vec<i128> = raw
        .iter()
        .map(|&v| if v.is_finite() { to_ns(v) } else { i128::MAX })
        .collect();
    let earliest = abs.iter().copied().min().unwrap_or(i128::MAX);
    let base = earliest.min(i128::from(scan.stamp_ns)).max(0);
    let span = abs
        .iter()
        .filter(|&&a| a != i128::MAX)
        .map(|&a| a - base)
        .max()
        .unwrap_or(0);
    scan.span_ns = u64::try_from(span).unwrap_or(u64::MAX);
    scan.time = PointTime::Field {
        name,
        unit,
        absolute,
    };
    if scan.span_ns > MAX_SPAN_NS {
        scan.time_dropped = true;
        return;
    }
    scan.stamp_ns = base as u64;
    for (p, a) in scan.cloud.points.iter_mut().zip(abs) {
        p.t_ns = if a == i128::MAX { 0 } else { (a - base) as u32 };
    }
}
