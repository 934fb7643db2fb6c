//! An analytic, smooth 6-DoF motion of the IMU and the exact IMU readings and sensor poses
//! it produces, in `f32`, without tables or files.
//!
//! Every coordinate (roll, pitch, yaw of `R_g_i`, and x, y, z of `p_g_i`) is a [`Bump`]
//! `a * ((1 - cos(w t)) / 2)^2`, whose value, velocity and acceleration are all zero at
//! `t = 0`: the IMU starts at rest, level and at the origin, so the filter's `at_rest`
//! initialisation is exact. Different frequencies per axis excite every rotation axis,
//! which the motion-based (hand-eye) extrinsic needs to be observable.
//!
//! Frames follow docs/formats.md: `G` is z-up with gravity `(0, 0, -9.81)`,
//! `R_g_i` is the orientation of the IMU in `G` (ZYX Euler: `Rz(yaw) Ry(pitch) Rx(roll)`,
//! nalgebra's `from_euler_angles`), the accelerometer measures the specific force
//! `R_g_i^T (a_g - g_g)` and the gyroscope `omega` in the IMU frame.

use libm::{cosf, sinf};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Gravity magnitude, m/s^2 (`g_g = (0, 0, -GRAVITY)`).
pub const GRAVITY: f32 = 9.81;

/// `a * ((1 - cos(w t)) / 2)^2` and its first two time derivatives.
#[derive(Clone, Copy, Debug)]
pub struct Bump {
    /// Peak value (reached where `cos(w t) = -1`).
    pub amplitude: f32,
    /// Angular frequency, rad/s.
    pub omega: f32,
}

impl Bump {
    /// A bump of peak `amplitude` and angular frequency `omega` (rad/s).
    pub const fn new(amplitude: f32, omega: f32) -> Self {
        Self { amplitude, omega }
    }

    /// Value, first and second derivative at `t` seconds.
    pub fn eval(&self, t: f32) -> [f32; 3] {
        let (a, w) = (self.amplitude, self.omega);
        let (s, c) = (sinf(w * t), cosf(w * t));
        let h = 0.5 * (1.0 - c); // in [0, 1]
        let dh = 0.5 * w * s;
        let ddh = 0.5 * w * w * c;
        [a * h * h, a * 2.0 * h * dh, a * 2.0 * (dh * dh + h * ddh)]
    }
}

/// The kinematic state of the IMU at one instant.
#[derive(Clone, Copy, Debug)]
pub struct ImuKinematics {
    /// `T_g_i`: pose of the IMU in `G`.
    pub t_g_i: Isometry3<f32>,
    /// Velocity of the IMU in `G`, m/s.
    pub v_in_g: Vector3<f32>,
    /// Angular velocity in the IMU frame, rad/s (what a perfect gyroscope reads).
    pub omega_in_imu: Vector3<f32>,
    /// Specific force in the IMU frame, m/s^2 (what a perfect accelerometer reads).
    pub specific_force_in_imu: Vector3<f32>,
}

/// The synthetic motion: three rotation bumps (roll, pitch, yaw) and three translation
/// bumps (x, y, z).
#[derive(Clone, Copy, Debug)]
pub struct Trajectory {
    /// Roll, pitch, yaw of `R_g_i`, rad.
    pub angles: [Bump; 3],
    /// x, y, z of `p_g_i`, m.
    pub position: [Bump; 3],
}

impl Trajectory {
    /// A hand-held-like motion: up to ~30 deg about each axis, ~0.5 m, ~3 m/s^2, periods
    /// 1.1-2.5 s, so a 3 s run contains more than one full swing on every axis.
    pub const fn handheld() -> Self {
        const TAU: f32 = core::f32::consts::TAU;
        Self {
            angles: [
                Bump::new(0.45, TAU * 0.9),
                Bump::new(-0.40, TAU * 0.7),
                Bump::new(0.60, TAU * 0.45),
            ],
            position: [
                Bump::new(0.50, TAU * 0.4),
                Bump::new(-0.35, TAU * 0.6),
                Bump::new(0.20, TAU * 0.8),
            ],
        }
    }

    /// The IMU's pose, velocity and ideal readings at `t` seconds after the start.
    pub fn kinematics(&self, t: f32) -> ImuKinematics {
        let [roll, pitch, yaw] = self.angles.map(|b| b.eval(t));
        let [x, y, z] = self.position.map(|b| b.eval(t));
        let r_g_i = UnitQuaternion::from_euler_angles(roll[0], pitch[0], yaw[0]);

        // Body rates of ZYX Euler angles (phi = roll, theta = pitch, psi = yaw).
        let (sphi, cphi) = (sinf(roll[0]), cosf(roll[0]));
        let (sth, cth) = (sinf(pitch[0]), cosf(pitch[0]));
        let (dphi, dth, dpsi) = (roll[1], pitch[1], yaw[1]);
        let omega_in_imu = Vector3::new(
            dphi - dpsi * sth,
            dth * cphi + dpsi * sphi * cth,
            -dth * sphi + dpsi * cphi * cth,
        );

        let a_in_g = Vector3::new(x[2], y[2], z[2]);
        let minus_g_in_g = Vector3::new(0.0, 0.0, GRAVITY);
        ImuKinematics {
            t_g_i: Isometry3::from_parts(Translation3::new(x[0], y[0], z[0]), r_g_i),
            v_in_g: Vector3::new(x[1], y[1], z[1]),
            omega_in_imu,
            specific_force_in_imu: r_g_i.inverse_transform_vector(&(a_in_g + minus_g_in_g)),
        }
    }

    /// Pose `T_s_from_s_to` of sensor S at `t_to` seen from its pose at `t_from`, for a sensor
    /// mounted at `t_i_s` (pose of S in the IMU frame): what S's odometry reports as one
    /// increment, `T_g_s(t_from)^-1 * T_g_s(t_to)` with `T_g_s = T_g_i * T_i_s`.
    pub fn sensor_increment(
        &self,
        t_i_s: &Isometry3<f32>,
        t_from: f32,
        t_to: f32,
    ) -> Isometry3<f32> {
        let t_g_s_from = self.kinematics(t_from).t_g_i * t_i_s;
        let t_g_s_to = self.kinematics(t_to).t_g_i * t_i_s;
        t_g_s_from.inv_mul(&t_g_s_to)
    }
}
