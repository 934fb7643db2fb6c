//! The motion of an intrinsics recording: the rig is waved in front of the static target so
//! that the target's centre sweeps a Lissajous figure (3 : 4 cycles) over cam0's image,
//! reaching within a margin of every edge and corner, while the target tilts up to
//! `max_tilt_rad` about both in-plane axes (2.5 and 1.5 cycles), rolls up to 0.35 rad (1
//! cycle) and the distance breathes between 0.8 and 1.25 times the nominal (2 cycles), all
//! over one period of the recording. Every term is a sinusoid of random phase: the pose is smooth
//! (C-infinity) in time. The nominal distance makes the target's larger side span
//! `target_fraction` of the image width at the centre of the image, measured with the
//! camera's own rays, so every lens model sees the target at a similar size.

use std::f64::consts::TAU;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;

use super::models::SimCamera;

/// The sweep of the target over cam0's image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sweep {
    /// Image point the target centre sweeps about (px).
    pub centre_px: Vector2<f64>,
    /// Half extent of the sweep (px).
    pub amplitude_px: Vector2<f64>,
    /// Nominal distance from the camera to the target centre, m.
    pub distance_m: f64,
    /// Largest tilt of the target about its in-plane axes, rad.
    pub max_tilt_rad: f64,
    /// Phases of the seven terms (u, v, tilt x, tilt y, roll, distance, spare), rad.
    pub phases: [f64; 7],
    /// The rotation taking the target frame to a camera looking straight at it (target
    /// up on the sheet = image up).
    pub r_facing: UnitQuaternion<f64>,
    /// The target centre in the target frame, m.
    pub centre_target: Vector3<f64>,
    /// cam0's [`SimCamera::max_angle`], computed once.
    pub max_angle: f64,
}

/// A target as the motion needs it: its centre, its larger side and how it faces a camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetGeometry {
    /// Centre of the corner pattern, target frame, m.
    pub centre: Vector3<f64>,
    /// Larger side of the corner pattern, m.
    pub size_m: f64,
    /// `R_cam_target` of a camera looking straight at the printed face, upright.
    pub r_facing: UnitQuaternion<f64>,
}

impl TargetGeometry {
    /// Facing for a target whose x runs down the sheet and y right (Kalibr checkerboard).
    pub fn checkerboard_facing() -> UnitQuaternion<f64> {
        rotation(Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0))
    }

    /// Facing for a target whose x runs right and y up the sheet (Kalibr AprilGrid).
    pub fn aprilgrid_facing() -> UnitQuaternion<f64> {
        rotation(Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0))
    }
}

fn rotation(m: Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

impl Sweep {
    /// A sweep for `camera` and `target`: the target spans `target_fraction` of the image
    /// width at the nominal distance; the sweep keeps the centre `margin_fraction` of the
    /// image size from every edge; random phases from `rng`.
    pub fn new(
        camera: &SimCamera,
        target: &TargetGeometry,
        target_fraction: f64,
        margin_fraction: f64,
        max_tilt_rad: f64,
        rng: &mut impl Rng,
    ) -> Option<Self> {
        let [w, h] = camera.resolution.map(f64::from);
        let centre_px = Vector2::new(0.5 * w - 0.5, 0.5 * h - 0.5);
        let half = 0.5 * target_fraction * w;
        let left = camera.unproject(&Vector2::new(camera.cu - half, camera.cv))?;
        let right = camera.unproject(&Vector2::new(camera.cu + half, camera.cv))?;
        let angle = left.angle(&right);
        let distance_m = 0.5 * target.size_m / (0.5 * angle).tan();
        Some(Self {
            centre_px,
            amplitude_px: Vector2::new((0.5 - margin_fraction) * w, (0.5 - margin_fraction) * h),
            distance_m,
            max_tilt_rad,
            phases: std::array::from_fn(|_| rng.gen_range(0.0..TAU)),
            r_facing: target.r_facing,
            centre_target: target.centre,
            max_angle: camera.max_angle(),
        })
    }

    /// `T_cam0_target` at phase `s` (0..1 over the recording), using `camera` (cam0) to turn
    /// the sweep's pixel into a direction.
    pub fn t_cam_target(&self, camera: &SimCamera, s: f64) -> Option<Isometry3<f64>> {
        let ph = &self.phases;
        let wave = |cycles: f64, k: usize| (TAU * cycles * s + ph[k]).sin();
        let px = self.centre_px
            + Vector2::new(
                self.amplitude_px.x * wave(3.0, 0),
                self.amplitude_px.y * wave(4.0, 1),
            );
        let dir = camera.unproject_within(&px, self.max_angle)?;
        let distance = self.distance_m * (1.025 + 0.225 * wave(2.0, 5));
        let look = UnitQuaternion::rotation_between(&Vector3::z(), &dir)
            .unwrap_or_else(UnitQuaternion::identity);
        let tilt = UnitQuaternion::from_euler_angles(
            self.max_tilt_rad * wave(2.5, 2),
            self.max_tilt_rad * wave(1.5, 3),
            0.35 * wave(1.0, 4),
        );
        let r_c_t = look * tilt * self.r_facing;
        let p = dir * distance - r_c_t * self.centre_target;
        Some(Isometry3::from_parts(Translation3::from(p), r_c_t))
    }
}
