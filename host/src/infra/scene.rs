//! The simulated building: an indoor loop (rounded rectangle, ~150 m) under a textured
//! ceiling, static infrastructure cameras at 3 m looking down at the corridor, and the
//! robot's true motion (pose of its upward fisheye `F` in the world `W`, z up).

use msreg_estimator::camera::{
    equidistant::Equidistant, radtan::RadTan, Camera, Distortion, Intrinsics, Projection,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;

/// Building and robot-path parameters.
#[derive(Clone, Debug)]
pub struct SceneConfig {
    /// Straight length along x of the loop's bounding rectangle, m.
    pub size_x: f64,
    /// Straight length along y, m.
    pub size_y: f64,
    /// Corner radius, m.
    pub corner_radius: f64,
    /// Robot speed, m/s.
    pub speed: f64,
    /// Height of `F` above the floor, m.
    pub f_height: f64,
    /// Ceiling height, m.
    pub ceiling_z: f64,
    /// Ceiling texture points per square metre (within `ceiling_band` of the path).
    pub ceiling_density: f64,
    /// Half-width of the textured ceiling band around the path, m.
    pub ceiling_band: f64,
    /// Number of infrastructure cameras.
    pub cameras: usize,
    /// Mounting height of the infrastructure cameras, m.
    pub camera_z: f64,
    /// Gap left between the end and the start of the drive, m.
    pub end_gap: f64,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            size_x: 55.0,
            size_y: 24.0,
            corner_radius: 3.0,
            speed: 0.8,
            f_height: 0.5,
            ceiling_z: 3.4,
            ceiling_density: 0.6,
            ceiling_band: 5.0,
            cameras: 40,
            camera_z: 3.0,
            end_gap: 1.0,
        }
    }
}

/// One static infrastructure camera.
#[derive(Clone, Debug)]
pub struct InfraCamera {
    /// Name (`c00`, `c01`, ...), the directory under `infra/`.
    pub id: String,
    /// Intrinsics and lens.
    pub camera: Camera<f64>,
    /// True pose `T_W_C`.
    pub t_world_cam: Isometry3<f64>,
    /// Frame period of its own free-running clock, s.
    pub period_s: f64,
    /// Time of its first frame after the start, s.
    pub phase_s: f64,
}

/// The rounded-rectangle loop: position and unit tangent at arc length `s`.
#[derive(Clone, Debug)]
pub struct LoopPath {
    hx: f64,
    hy: f64,
    r: f64,
}

impl LoopPath {
    /// The loop of a scene.
    pub fn new(c: &SceneConfig) -> Self {
        Self {
            hx: c.size_x / 2.0,
            hy: c.size_y / 2.0,
            r: c.corner_radius,
        }
    }

    /// Perimeter, m.
    pub fn length(&self) -> f64 {
        4.0 * (self.hx - self.r) + 4.0 * (self.hy - self.r) + 2.0 * std::f64::consts::PI * self.r
    }

    /// Point and unit tangent at arc length `s` (wrapped), counter-clockwise from the middle
    /// of the bottom edge.
    pub fn at(&self, s: f64) -> (Vector2<f64>, Vector2<f64>) {
        let (ax, ay, r) = (self.hx - self.r, self.hy - self.r, self.r);
        let arc = std::f64::consts::FRAC_PI_2 * r;
        // Segments: bottom half-edge, corner, right, corner, top, corner, left, corner, rest.
        let segs = [ax, arc, 2.0 * ay, arc, 2.0 * ax, arc, 2.0 * ay, arc, ax];
        let mut s = s.rem_euclid(self.length());
        let centres = [(ax, -ay), (ax, ay), (-ax, ay), (-ax, -ay)];
        let starts = [
            (0.0, -self.hy),
            (self.hx, -ay),
            (ax, self.hy),
            (-self.hx, ay),
        ];
        let dirs = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)];
        for (i, len) in segs.iter().enumerate() {
            if s <= *len || i == segs.len() - 1 {
                if i % 2 == 0 {
                    let k = (i / 2) % 4;
                    let (sx, sy) = if i == 8 { (-ax, -self.hy) } else { starts[k] };
                    let d = Vector2::new(dirs[k].0, dirs[k].1);
                    return (Vector2::new(sx, sy) + d * s, d);
                }
                let (cx, cy) = centres[i / 2];
                let a0 =
                    -std::f64::consts::FRAC_PI_2 + (i / 2) as f64 * std::f64::consts::FRAC_PI_2;
                let a = a0 + s / r;
                let p = Vector2::new(cx + r * a.cos(), cy + r * a.sin());
                return (p, Vector2::new(-a.sin(), a.cos()));
            }
            s -= len;
        }
        unreachable!("the last segment takes any remainder")
    }
}

/// The robot's true motion: `T_W_F(t)`, t in seconds from the start.
#[derive(Clone, Debug)]
pub struct RobotMotion {
    path: LoopPath,
    speed: f64,
    height: f64,
    /// Duration of the drive, s.
    pub duration_s: f64,
}

impl RobotMotion {
    /// Once round the loop, ending `end_gap` short of the start.
    pub fn new(c: &SceneConfig) -> Self {
        let path = LoopPath::new(c);
        let duration_s = (path.length() - c.end_gap) / c.speed;
        Self {
            path,
            speed: c.speed,
            height: c.f_height,
            duration_s,
        }
    }

    /// `T_W_F(t)`: F looks up (z_F = up), x_F forward; +-1.5 deg of suspension roll and
    /// pitch and 1 cm of bounce, so the motion is not exactly planar.
    pub fn pose(&self, t: f64) -> Isometry3<f64> {
        let (p, d) = self.path.at(self.speed * t);
        let yaw = d.y.atan2(d.x);
        let roll = 1.5f64.to_radians() * (std::f64::consts::TAU * t / 7.3).sin();
        let pitch = 1.5f64.to_radians() * (std::f64::consts::TAU * t / 5.1 + 1.0).sin();
        let z = self.height + 0.01 * (std::f64::consts::TAU * t / 3.7).sin();
        let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        Isometry3::from_parts(Translation3::new(p.x, p.y, z), q)
    }

    /// The path.
    pub fn path(&self) -> &LoopPath {
        &self.path
    }
}

/// Ceiling texture points within the band around the path.
pub fn ceiling_points<R: Rng>(c: &SceneConfig, rng: &mut R) -> Vec<Vector3<f64>> {
    let hx = c.size_x / 2.0 + c.ceiling_band;
    let hy = c.size_y / 2.0 + c.ceiling_band;
    let area = 4.0 * hx * hy;
    let n = (area * c.ceiling_density) as usize;
    let inner_x = c.size_x / 2.0 - c.ceiling_band;
    let inner_y = c.size_y / 2.0 - c.ceiling_band;
    (0..n)
        .map(|_| Vector2::new(rng.gen_range(-hx..hx), rng.gen_range(-hy..hy)))
        .filter(|p| p.x.abs() > inner_x || p.y.abs() > inner_y)
        .map(|p| Vector3::new(p.x, p.y, c.ceiling_z))
        .collect()
}

/// The robot's fisheye `F`: equidistant, 1024 x 1024, about 190 deg field of view.
pub fn robot_fisheye() -> Camera<f64> {
    let lens = Equidistant {
        k1: 0.02,
        k2: -0.005,
        k3: 0.001,
        k4: 0.0,
    };
    let k = Intrinsics {
        fu: 300.0,
        fv: 300.0,
        cu: 511.5,
        cv: 511.5,
    };
    Camera::new(
        Projection::Pinhole,
        k,
        Distortion::Equidistant(lens),
        (1024, 1024),
    )
    .expect("valid fixed camera")
}

fn infra_lens(fisheye: bool) -> Camera<f64> {
    if fisheye {
        let lens = Equidistant {
            k1: -0.01,
            k2: 0.003,
            k3: 0.0,
            k4: 0.0,
        };
        let k = Intrinsics {
            fu: 260.0,
            fv: 260.0,
            cu: 399.5,
            cv: 399.5,
        };
        Camera::new(
            Projection::Pinhole,
            k,
            Distortion::Equidistant(lens),
            (800, 800),
        )
        .expect("valid fixed camera")
    } else {
        let lens = RadTan {
            k1: -0.08,
            k2: 0.02,
            p1: 0.0005,
            p2: -0.0003,
            k3: 0.0,
        };
        let k = Intrinsics {
            fu: 520.0,
            fv: 520.0,
            cu: 639.5,
            cv: 359.5,
        };
        Camera::new(
            Projection::Pinhole,
            k,
            Distortion::RadTan(lens),
            (1280, 720),
        )
        .expect("valid fixed camera")
    }
}

/// ~`c.cameras` cameras spread along the loop, alternately left and right of it, each looking
/// down at 30-70 deg towards a point of the path; every other one a fisheye.
pub fn infra_cameras<R: Rng>(c: &SceneConfig, path: &LoopPath, rng: &mut R) -> Vec<InfraCamera> {
    let spacing = path.length() / c.cameras as f64;
    let marker_z = c.f_height + 0.05;
    (0..c.cameras)
        .map(|k| {
            let s = (k as f64 + rng.gen_range(0.2..0.8)) * spacing;
            let (p, d) = path.at(s);
            let left = Vector2::new(-d.y, d.x);
            let side = if k % 2 == 0 { 1.0 } else { -1.0 };
            let depression = rng.gen_range(30.0f64..70.0).to_radians();
            // The horizontal distance to the target sets the depression; it is split into an
            // offset along the path and one across it.
            let horizontal = (c.camera_z - marker_z) / depression.tan();
            let along = rng.gen_range(-0.5..0.5) * horizontal;
            let lateral = (horizontal * horizontal - along * along).sqrt();
            let target = Vector3::new(p.x, p.y, marker_z);
            let centre_xy = p + left * side * lateral + d * along;
            let centre = Vector3::new(centre_xy.x, centre_xy.y, c.camera_z);
            InfraCamera {
                id: format!("c{k:02}"),
                camera: infra_lens(k % 2 == 1),
                t_world_cam: look_at(&centre, &target, rng.gen_range(-0.3..0.3)),
                period_s: 1.0 / rng.gen_range(9.5..10.5),
                phase_s: rng.gen_range(0.0..0.1),
            }
        })
        .collect()
}

/// `T_W_C` of a camera at `centre` whose optical axis points at `target`, rolled by `roll`.
pub fn look_at(centre: &Vector3<f64>, target: &Vector3<f64>, roll: f64) -> Isometry3<f64> {
    let z = (target - centre).normalize();
    let x0 = z.cross(&Vector3::z()).normalize();
    let y0 = z.cross(&x0);
    let (x, y) = (
        x0 * roll.cos() + y0 * roll.sin(),
        -x0 * roll.sin() + y0 * roll.cos(),
    );
    let m = nalgebra::Matrix3::from_columns(&[x, y, z]);
    let r = nalgebra::Rotation3::from_matrix_unchecked(m);
    Isometry3::from_parts(
        Translation3::from(*centre),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loop_is_continuous_and_closed() {
        let path = LoopPath::new(&SceneConfig::default());
        let n = 20000;
        let step = path.length() / n as f64;
        for i in 0..=n {
            let s = i as f64 * step;
            let (a, da) = path.at(s);
            let (b, _) = path.at(s + step);
            assert!(
                ((b - a).norm() - step).abs() < 1e-3 * step + 1e-9,
                "jump at s = {s}"
            );
            assert!((da.norm() - 1.0).abs() < 1e-12);
        }
        assert!((path.length() - 152.85).abs() < 0.1, "{}", path.length());
    }

    #[test]
    fn cameras_look_down_30_to_70_degrees() {
        let c = SceneConfig::default();
        let path = LoopPath::new(&c);
        for seed in 0..20 {
            let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed);
            for cam in infra_cameras(&c, &path, &mut rng) {
                let axis = cam.t_world_cam.rotation * Vector3::z();
                let depression = (-axis.z).asin().to_degrees();
                assert!((29.9..70.1).contains(&depression), "{depression}");
                let y_down = cam.t_world_cam.rotation * Vector3::y();
                assert!(y_down.z < 0.0, "image y must point down-ish");
            }
        }
    }
}
