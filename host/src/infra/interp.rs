//! The metric VO trajectory of `F` and its interpolation at any stamp (eq. 6.3-6.6): linear
//! in position, slerp in rotation between the bracketing keyframes.

use nalgebra::{Isometry3, Translation3};

use super::colmap::ColmapModel;

/// Keyframe poses `T_vo_F` in the frame of the first keyframe, with a scale applied.
#[derive(Clone, Debug)]
pub struct KeyframeTrack {
    /// Keyframe stamps, ns, ascending.
    pub stamps: Vec<u64>,
    /// `T_F0_Fk` in VO units (unscaled).
    pub unscaled: Vec<Isometry3<f64>>,
}

impl KeyframeTrack {
    /// From a COLMAP model (world-to-camera poses inverted, re-expressed in `F_0`).
    pub fn from_model(model: &ColmapModel) -> Self {
        let stamps = model.images.iter().map(|i| i.stamp_ns).collect();
        let first = model
            .images
            .first()
            .map(|i| i.t_cam_world)
            .unwrap_or_else(Isometry3::identity);
        let unscaled = model
            .images
            .iter()
            .map(|i| first * i.t_cam_world.inverse())
            .collect();
        Self { stamps, unscaled }
    }

    /// `T_vo_F` of keyframe `k` at `scale` metres per VO unit.
    pub fn keyframe(&self, k: usize, scale: f64) -> Isometry3<f64> {
        let t = self.unscaled[k];
        Isometry3::from_parts(Translation3::from(t.translation.vector * scale), t.rotation)
    }

    /// Bracketing keyframes `(i, j, alpha)` of a stamp (eq. 6.3), `None` outside the span.
    pub fn bracket(&self, stamp_ns: u64) -> Option<(usize, usize, f64)> {
        let j = self.stamps.partition_point(|&s| s < stamp_ns);
        if j < self.stamps.len() && self.stamps[j] == stamp_ns {
            return Some((j, j, 0.0));
        }
        if j == 0 || j == self.stamps.len() {
            return None;
        }
        let alpha =
            (stamp_ns - self.stamps[j - 1]) as f64 / (self.stamps[j] - self.stamps[j - 1]) as f64;
        Some((j - 1, j, alpha))
    }

    /// `T_vo_F(t)` (eq. 6.3-6.6), `None` outside the keyframes' span.
    pub fn at(&self, stamp_ns: u64, scale: f64) -> Option<Isometry3<f64>> {
        let j = self.stamps.partition_point(|&s| s < stamp_ns);
        if j < self.stamps.len() && self.stamps[j] == stamp_ns {
            return Some(self.keyframe(j, scale));
        }
        if j == 0 || j == self.stamps.len() {
            return None;
        }
        let i = j - 1;
        let alpha = (stamp_ns - self.stamps[i]) as f64 / (self.stamps[j] - self.stamps[i]) as f64;
        let (a, b) = (self.keyframe(i, scale), self.keyframe(j, scale));
        let p = a.translation.vector * (1.0 - alpha) + b.translation.vector * alpha;
        let q = a.rotation.slerp(&b.rotation, alpha);
        Some(Isometry3::from_parts(Translation3::from(p), q))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    #[test]
    fn interpolates_between_keyframes() {
        let a = Isometry3::identity();
        let b = Isometry3::from_parts(
            Translation3::new(2.0, 0.0, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
        );
        let track = KeyframeTrack {
            stamps: vec![100, 200],
            unscaled: vec![a, b],
        };
        let m = track.at(150, 3.0).expect("inside");
        assert!((m.translation.vector - Vector3::new(3.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((m.rotation.angle() - 0.2).abs() < 1e-12);
        assert!(track.at(99, 1.0).is_none() && track.at(201, 1.0).is_none());
        assert!((track.at(200, 1.0).expect("end").translation.vector.x - 2.0).abs() < 1e-12);
    }
}
