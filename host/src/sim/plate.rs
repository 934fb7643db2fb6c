//! A thin rectangular plate in the scene (a calibration board): what a ray-cast LiDAR sees of
//! it is the rectangle, from either side.

use nalgebra::{Isometry3, Vector3};

/// A rectangle `|x| <= half_extents.0`, `|y| <= half_extents.1` of the plane `z = 0` of its
/// own frame P, placed at `T_G_P`.
#[derive(Debug, Clone, PartialEq)]
pub struct Plate {
    /// Pose of the plate's centre frame in G (z: the plate normal).
    pub t_g_p: Isometry3<f64>,
    /// Half width (along P x) and half height (along P y), m.
    pub half_extents: (f64, f64),
    /// Reflectivity of its surface (Ouster-like units, 1-100).
    pub reflectivity: f32,
}

impl Plate {
    /// Range along the unit ray `origin + s dir` (`s > 0`) to the plate and the cosine of the
    /// incidence angle; `None` when the ray misses it.
    pub fn hit(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<(f64, f32)> {
        let r = self.t_g_p.rotation;
        let normal = r * Vector3::z();
        let centre = self.t_g_p.translation.vector;
        let denom = normal.dot(dir);
        if denom.abs() < 1e-12 {
            return None;
        }
        let s = normal.dot(&(centre - origin)) / denom;
        if s <= 0.0 {
            return None;
        }
        let local = r.inverse() * (origin + dir * s - centre);
        let inside = local.x.abs() <= self.half_extents.0 && local.y.abs() <= self.half_extents.1;
        inside.then_some((s, denom.abs() as f32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn rays_hit_inside_and_miss_outside_the_rectangle() {
        let plate = Plate {
            t_g_p: Isometry3::from_parts(
                Translation3::new(2.0, 0.0, 1.0),
                UnitQuaternion::from_euler_angles(0.0, -std::f64::consts::FRAC_PI_2, 0.0),
            ),
            half_extents: (0.4, 0.3),
            reflectivity: 80.0,
        };
        let origin = Vector3::new(0.0, 0.0, 1.0);
        let hit = plate.hit(&origin, &Vector3::x()).expect("straight ahead");
        assert!((hit.0 - 2.0).abs() < 1e-12 && (hit.1 - 1.0).abs() < 1e-6);
        // 0.25 m sideways (inside the 0.3 m half height along P y = G y) and 0.5 m up
        // (outside the 0.4 m half width along P x = G z).
        let inside = Vector3::new(2.0, 0.25, 0.0).normalize();
        assert!(plate.hit(&origin, &inside).is_some());
        let outside = Vector3::new(2.0, 0.0, 0.5).normalize();
        assert!(plate.hit(&origin, &outside).is_none());
        assert!(plate.hit(&origin, &-Vector3::x()).is_none());
    }
}
