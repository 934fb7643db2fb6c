//! Deskewing (motion compensation, eq. 3.18) with the filter's own IMU poses.
//!
//! The pipeline pushes the filter's nominal pose `T_G_I` into a [`PoseBuffer`] after every
//! IMU sample. Point `i` of a scan stamped `s`, fired at IMU time `s + t_i + t_d`, is moved
//! into the LiDAR frame at a reference time `t_ref` (the scan's last firing):
//!
//! `p_Lref = T_I_L^-1 T_G_I(t_ref)^-1 T_G_I(t_i) T_I_L p_Li`
//!
//! Poses between buffered samples are interpolated (slerp / lerp; at 400 Hz the IMU moves
//! ~2.5 ms between samples, far below the deskew's sensitivity). Only relative poses within
//! a sweep are used, so a constant error of the buffered trajectory cancels. When an update
//! corrects the filter's current pose, [`PoseBuffer::reanchor`] moves every buffered pose
//! by the same correction so the buffer stays a continuous trajectory.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::pointcloud::{Point, PointCloud};

/// Recent `(stamp_ns, T_G_I)` of the filter, IMU clock, strictly increasing stamps.
#[derive(Debug, Clone, Default)]
pub struct PoseBuffer {
    poses: VecDeque<(u64, Isometry3<f64>)>,
    keep_ns: u64,
}

impl PoseBuffer {
    /// A buffer that keeps the last `keep_ns` of poses.
    pub fn new(keep_ns: u64) -> Self {
        Self {
            poses: VecDeque::new(),
            keep_ns,
        }
    }

    /// Appends a pose; a stamp not after the last one replaces the last pose.
    pub fn push(&mut self, stamp_ns: u64, pose: Isometry3<f64>) {
        while self.poses.back().is_some_and(|(s, _)| *s >= stamp_ns) {
            self.poses.pop_back();
        }
        self.poses.push_back((stamp_ns, pose));
        let oldest = stamp_ns.saturating_sub(self.keep_ns);
        while self.poses.len() > 2 && self.poses.front().is_some_and(|(s, _)| *s < oldest) {
            self.poses.pop_front();
        }
    }

    /// Left-multiplies every buffered pose by `correction` (`T_G_new = correction T_G_old`).
    pub fn reanchor(&mut self, correction: &Isometry3<f64>) {
        for (_, pose) in &mut self.poses {
            *pose = correction * *pose;
        }
    }

    /// Number of buffered poses.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// Stamp of the newest pose.
    pub fn last_stamp(&self) -> Option<u64> {
        self.poses.back().map(|(s, _)| *s)
    }

    /// `T_G_I` at `stamp_ns`, interpolated; clamped to the oldest / newest pose outside.
    pub fn at(&self, stamp_ns: u64) -> Option<Isometry3<f64>> {
        let (first, last) = (self.poses.front()?, self.poses.back()?);
        if stamp_ns <= first.0 {
            return Some(first.1);
        }
        if stamp_ns >= last.0 {
            return Some(last.1);
        }
        let i = self.poses.partition_point(|(s, _)| *s <= stamp_ns);
        let (s0, p0) = self.poses.get(i.checked_sub(1)?)?;
        let (s1, p1) = self.poses.get(i)?;
        let f = (stamp_ns - s0) as f64 / (s1 - s0) as f64;
        Some(p0.lerp_slerp(p1, f))
    }
}

/// IMU time of LiDAR stamp `stamp_ns` plus `offset_ns`, with the time offset `td_ns`.
pub fn imu_time(stamp_ns: u64, offset_ns: u64, td_ns: i64) -> u64 {
    let t = i128::from(stamp_ns) + i128::from(offset_ns) + i128::from(td_ns);
    t.clamp(0, i128::from(u64::MAX)) as u64
}

/// A scan moved into the LiDAR frame at its reference time, with where each firing's rays
/// start in that frame: the LiDAR's origin at the firing time. A point is its ray's origin
/// plus its range along the ray, so a selection made on the ray (e.g. "the ray crosses the
/// board") is blind to the range noise, which a selection on the point's position is not.
#[derive(Debug, Clone, Default)]
pub struct DeskewedScan {
    /// The points in the reference frame.
    pub cloud: PointCloud,
    /// `(firing offset ns, ray origin)`, sorted by offset; empty when not deskewed.
    firing_origins: Vec<(u32, Vector3<f64>)>,
}

impl DeskewedScan {
    /// A scan left as it is (no motion compensation): every ray starts at the origin.
    pub fn undistorted(cloud: PointCloud) -> Self {
        Self {
            cloud,
            firing_origins: Vec::new(),
        }
    }

    /// The origin, in the reference frame, of the rays fired at offset `t_ns` (the frame's
    /// origin for a scan left as it is or an offset the scan does not have).
    pub fn ray_origin(&self, t_ns: u32) -> Vector3<f64> {
        self.firing_origins
            .binary_search_by_key(&t_ns, |(t, _)| *t)
            .map_or_else(|_| Vector3::zeros(), |i| self.firing_origins[i].1)
    }
}

/// Moves every point of `scan` (stamped `stamp_ns`, LiDAR clock) into the LiDAR frame at
/// LiDAR time `stamp_ns + ref_offset_ns` (eq. 3.18), with time offset `td_ns` and extrinsic
/// `t_i_l`. Consecutive points with the same firing offset share one transform.
pub fn deskew_scan(
    scan: &PointCloud,
    stamp_ns: u64,
    ref_offset_ns: u64,
    td_ns: i64,
    t_i_l: &Isometry3<f64>,
    buffer: &PoseBuffer,
) -> Option<DeskewedScan> {
    let t_g_iref = buffer.at(imu_time(stamp_ns, ref_offset_ns, td_ns))?;
    let head = t_i_l.inverse() * t_g_iref.inverse();
    let mut cached: Option<(u32, Isometry3<f64>)> = None;
    let mut points = Vec::with_capacity(scan.len());
    let mut firing_origins = Vec::new();
    for p in &scan.points {
        let transform = match cached {
            Some((t, m)) if t == p.t_ns => m,
            _ => {
                let t_g_i = buffer.at(imu_time(stamp_ns, u64::from(p.t_ns), td_ns))?;
                let m = head * t_g_i * t_i_l;
                cached = Some((p.t_ns, m));
                firing_origins.push((p.t_ns, m.translation.vector));
                m
            }
        };
        points.push(Point {
            xyz: (transform * Point3::from(p.xyz)).coords,
            ..*p
        });
    }
    firing_origins.sort_by_key(|(t, _)| *t);
    firing_origins.dedup_by_key(|(t, _)| *t);
    Some(DeskewedScan {
        cloud: PointCloud::new(points),
        firing_origins,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn motion(t: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.5 * t, -0.2 * t, 0.1 * t),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.3, -0.5, 1.2) * t),
        )
    }

    #[test]
    fn deskewing_undoes_known_motion() {
        let mut buffer = PoseBuffer::new(1_000_000_000);
        for k in 0..=200u64 {
            buffer.push(k * 1_000_000, motion(k as f64 * 1e-3));
        }
        let t_i_l = Isometry3::from_parts(
            Translation3::new(0.1, 0.05, -0.02),
            UnitQuaternion::from_euler_angles(3.0, 0.1, -1.0),
        );
        // A fixed world point observed at several firing times.
        let world = Point3::new(3.0, -1.0, 0.5);
        let points: Vec<Point> = (0..10u32)
            .map(|k| {
                let t_ns = k * 10_000_000;
                let t_g_l = motion(f64::from(t_ns) * 1e-9) * t_i_l;
                Point {
                    xyz: (t_g_l.inverse() * world).coords,
                    t_ns,
                    ..Point::default()
                }
            })
            .collect();
        let raw = PointCloud::new(points);
        let out = deskew_scan(&raw, 0, 90_000_000, 0, &t_i_l, &buffer).unwrap_or_default();
        let expected = ((motion(0.09) * t_i_l).inverse() * world).coords;
        assert_eq!(out.cloud.len(), 10);
        for (p, r) in out.cloud.points.iter().zip(&raw.points) {
            // The point lies its raw range away from its ray's origin, which is the LiDAR at
            // the firing time seen from the reference frame.
            let origin = out.ray_origin(p.t_ns);
            let truth = ((motion(0.09) * t_i_l).inverse()
                * (motion(f64::from(p.t_ns) * 1e-9) * t_i_l))
                .translation
                .vector;
            assert!(
                (origin - truth).norm() < 1e-5,
                "{}",
                (origin - truth).norm()
            );
            assert!(((p.xyz - origin).norm() - r.xyz.norm()).abs() < 1e-9);
        }
        for p in out.cloud.points {
            // Linear interpolation of a 1 ms spaced buffer: sub-micrometre.
            assert!(
                (p.xyz - expected).norm() < 1e-5,
                "{}",
                (p.xyz - expected).norm()
            );
        }
    }

    #[test]
    fn reanchoring_keeps_relative_poses() {
        let mut buffer = PoseBuffer::new(1_000_000_000);
        for k in 0..10u64 {
            buffer.push(k * 1_000_000, motion(k as f64 * 1e-3));
        }
        let rel = |b: &PoseBuffer| {
            b.at(2_000_000)
                .zip(b.at(7_500_000))
                .map(|(a, c)| a.inverse() * c)
        };
        let before = rel(&buffer);
        buffer.reanchor(&motion(3.0));
        let after = rel(&buffer);
        let (Some(before), Some(after)) = (before, after) else {
            panic!("buffer empty");
        };
        assert!((before.translation.vector - after.translation.vector).norm() < 1e-12);
    }
}
