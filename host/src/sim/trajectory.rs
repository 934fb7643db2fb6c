//! A smooth, excitation-rich hand-held IMU trajectory `T_G_I(t)` with exact
//! analytic velocity, body angular rate and specific force.
//!
//! Position and the ZYX Euler angles (roll, pitch, yaw; `R_G_I = Rz(yaw)
//! Ry(pitch) Rx(roll)`) are each a base value plus a smooth step times a sum
//! of sinusoids. The body rate follows exactly from the Euler-rate kinematics
//! `omega_I = E(roll, pitch) * [roll', pitch', yaw']`, the specific force from
//! `f_I = R_G_I^T (p''(t) - g)`. Roll and pitch amplitudes are capped so
//! the motion stays far from the pitch = +-90 deg singularity.

use std::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;

use super::drive::{Drive, DriveConfig};
use super::signal::{EnvelopedSignal, Jet, Sinusoid, SmoothStep};

/// Standard gravity [m/s^2]; gravity in `G` is `(0, 0, -GRAVITY)`.
pub const GRAVITY: f64 = 9.81;

/// Gravity vector in `G`.
pub fn gravity_in_g() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -GRAVITY)
}

/// Shape of the random trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryConfig {
    /// Still period at the start (s) (for bias/gravity initialisation).
    pub stationary_s: f64,
    /// Duration of the smooth-step fade-in after it (s), > 0.
    pub ramp_s: f64,
    /// Sinusoids per position axis and per Euler angle.
    pub sinusoids_per_axis: usize,
    /// Lowest sinusoid frequency (Hz).
    pub min_frequency_hz: f64,
    /// Highest sinusoid frequency (Hz).
    pub max_frequency_hz: f64,
    /// Angular-rate amplitude of each Euler-angle sinusoid [rad/s].
    pub rate_amplitude_rad_s: f64,
    /// Speed amplitude of each position sinusoid [m/s].
    pub speed_amplitude_m_s: f64,
    /// Cap on the summed roll amplitudes (rad).
    pub max_roll_amplitude_rad: f64,
    /// Cap on the summed pitch amplitudes (rad) (keeps away from gimbal lock).
    pub max_pitch_amplitude_rad: f64,
    /// Which motion [`Trajectory::random`] draws; the fields above shape the hand-held one
    /// (the look-at trajectory ignores this).
    pub motion: MotionKind,
}

/// The kind of motion of [`Trajectory::random`].
#[derive(Debug, Clone, PartialEq, Default)]
pub enum MotionKind {
    /// Hand-held: sinusoids on every axis after a still start.
    #[default]
    Handheld,
    /// A car on a plane ([`super::drive`]): rotation mostly about one axis, moving from the
    /// first sample on.
    Drive(DriveConfig),
}

impl Default for TrajectoryConfig {
    fn default() -> Self {
        Self {
            stationary_s: 1.0,
            ramp_s: 1.0,
            sinusoids_per_axis: 3,
            min_frequency_hz: 0.2,
            max_frequency_hz: 1.2,
            rate_amplitude_rad_s: 0.9,
            speed_amplitude_m_s: 0.25,
            max_roll_amplitude_rad: 1.0,
            max_pitch_amplitude_rad: 0.7,
            motion: MotionKind::Handheld,
        }
    }
}

/// The ground-truth motion of the IMU in `G`.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Position and Euler-angle signals.
    signals: Signals,
    /// `None` for the plain hand-held trajectory and the drive.
    mount: Option<Mount>,
}

/// Where the position and the ZYX Euler angles come from.
#[derive(Debug, Clone, PartialEq)]
enum Signals {
    /// Enveloped sinusoids.
    Sinusoidal {
        /// `p_G_I` x, y, z (with a [`Mount`]: `p_W_F`).
        position: [EnvelopedSignal; 3],
        /// Roll, pitch, yaw of `R_G_I` (ZYX) (with a [`Mount`]: of `R_W_F`).
        euler: [EnvelopedSignal; 3],
    },
    /// A car-like drive.
    Drive(Drive),
}

/// Constant frames around the sinusoidal motion, for motions shaped in another frame than
/// the IMU's (the look-at trajectory of the camera simulator): the signals describe
/// `T_W_F(t)` of a frame `F` in a frame `W`, and `T_G_I(t) = T_G_W * T_W_F(t) * T_F_I`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mount {
    /// `T_G_W`: where the motion frame `W` is in `G`.
    pub t_g_w: Isometry3<f64>,
    /// `T_F_I`: the IMU in the moving frame `F` (e.g. `T_cam_imu`).
    pub t_f_i: Isometry3<f64>,
}

/// Shape of a look-at motion ([`Trajectory::random_look_at`]): a hand-held camera `F`
/// waved in front of a point `distance_m` ahead of it along its optical axis (`W` z; x right,
/// y down), translating and turning while its view direction follows the point to first
/// order, plus independent turns around that direction.
#[derive(Debug, Clone, PartialEq)]
pub struct LookAtConfig {
    /// Nominal distance from the camera to the looked-at point (m), > 0.
    pub distance_m: f64,
    /// Cap on the summed position amplitudes along `W` x, y, z (m).
    pub max_offset_m: [f64; 3],
    /// Cap on the summed amplitudes of the turns that are not look-at corrections: about
    /// `F` x (tilt), y (pan) and z (the optical axis), rad.
    pub max_deviation_rad: [f64; 3],
}

impl Trajectory {
    /// A random trajectory drawn from `rng` with the shape of `config` (hand-held or drive,
    /// [`TrajectoryConfig::motion`]).
    pub fn random(config: &TrajectoryConfig, rng: &mut impl Rng) -> Self {
        if let MotionKind::Drive(drive) = &config.motion {
            return Self {
                signals: Signals::Drive(Drive::random(drive, rng)),
                mount: None,
            };
        }
        let envelope = SmoothStep {
            start_s: config.stationary_s,
            duration_s: config.ramp_s,
        };
        let position_base = [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 1.0];
        let euler_base = [
            rng.gen_range(-0.2..0.2),
            rng.gen_range(-0.2..0.2),
            rng.gen_range(-PI..PI),
        ];
        let euler_cap = [
            config.max_roll_amplitude_rad,
            config.max_pitch_amplitude_rad,
            f64::INFINITY,
        ];
        let speed = config.speed_amplitude_m_s;
        let rate = config.rate_amplitude_rad_s;
        let position = position_base
            .map(|base| random_signal(config, envelope, rng, base, speed, f64::INFINITY));
        let euler = [0, 1, 2]
            .map(|k| random_signal(config, envelope, rng, euler_base[k], rate, euler_cap[k]));
        Self {
            signals: Signals::Sinusoidal { position, euler },
            mount: None,
        }
    }

    /// A look-at trajectory: `F` moves about the origin of `W` looking along `W` z at the
    /// point `(0, 0, look.distance_m)`. Position offsets are random sinusoids (speed
    /// amplitude and frequencies of `config`, capped by `look.max_offset_m`); each lateral
    /// offset `x` (`y`) is paired with a pan of `-x / d` (a tilt of `y / d`) with the same
    /// frequency and phase, which keeps the point centred to first order; independent turns
    /// (rate amplitude of `config`, capped by `look.max_deviation_rad`) come on top. The
    /// Euler angles stay small, far from their singularity; `config`'s roll/pitch caps are
    /// not used.
    pub fn random_look_at(
        config: &TrajectoryConfig,
        look: &LookAtConfig,
        mount: Mount,
        rng: &mut impl Rng,
    ) -> Self {
        let envelope = SmoothStep {
            start_s: config.stationary_s,
            duration_s: config.ramp_s,
        };
        let speed = config.speed_amplitude_m_s;
        let rate = config.rate_amplitude_rad_s;
        let position = [0, 1, 2]
            .map(|k| random_signal(config, envelope, rng, 0.0, speed, look.max_offset_m[k]));
        let mut euler = [0, 1, 2]
            .map(|k| random_signal(config, envelope, rng, 0.0, rate, look.max_deviation_rad[k]));
        // Small angles: R ~ I + [(roll, pitch, yaw)]x turns the optical axis to
        // (pitch, -roll, 1); the point seen from (x, y) lies along (-x, -y, d).
        let d = look.distance_m;
        let follow = |signal: &EnvelopedSignal, scale: f64| -> Vec<Sinusoid> {
            signal
                .sinusoids
                .iter()
                .map(|s| Sinusoid {
                    amplitude: s.amplitude * scale,
                    ..*s
                })
                .collect()
        };
        let tilt = follow(&position[1], 1.0 / d);
        let pan = follow(&position[0], -1.0 / d);
        euler[0].sinusoids.extend(tilt);
        euler[1].sinusoids.extend(pan);
        Self {
            signals: Signals::Sinusoidal { position, euler },
            mount: Some(mount),
        }
    }

    /// The same motion seen by a second body rigidly mounted at `t_i_b` (`T_I_B`, the body
    /// `B` in this trajectory's `I`): `T_G_B(t) = T_G_I(t) * T_I_B`, with its rate and
    /// acceleration still analytic (the lever-arm terms of [`Mount`]). A second IMU on the
    /// rig samples this trajectory.
    pub fn remounted(&self, t_i_b: &Isometry3<f64>) -> Self {
        let mount = match &self.mount {
            None => Mount {
                t_g_w: Isometry3::identity(),
                t_f_i: *t_i_b,
            },
            Some(m) => Mount {
                t_g_w: m.t_g_w,
                t_f_i: m.t_f_i * t_i_b,
            },
        };
        Self {
            signals: self.signals.clone(),
            mount: Some(mount),
        }
    }

    /// The constant frames of a look-at trajectory (`None` for the plain one).
    pub fn mount(&self) -> Option<&Mount> {
        self.mount.as_ref()
    }

    /// `(R_G_I, p_G_I)` at `t` [s since the start stamp].
    pub fn pose(&self, t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let [roll, pitch, yaw] = self.euler_jets(t);
        let r_g_i = UnitQuaternion::from_euler_angles(roll.v, pitch.v, yaw.v);
        let p: Vector3<f64> = self.position_jets(t).map(|j| j.v).into();
        match &self.mount {
            None => (r_g_i, p),
            Some(m) => {
                // Here `r_g_i` is R_W_F and `p` is p_W_F.
                let t_w_f = Isometry3::from_parts(Translation3::from(p), r_g_i);
                let t_g_i = m.t_g_w * t_w_f * m.t_f_i;
                (t_g_i.rotation, t_g_i.translation.vector)
            }
        }
    }

    /// `T_G_I` at `t`.
    pub fn isometry(&self, t: f64) -> Isometry3<f64> {
        let (r_g_i, p_g_i) = self.pose(t);
        Isometry3::from_parts(Translation3::from(p_g_i), r_g_i)
    }

    /// `v_G_I`, velocity of `I` in `G` [m/s].
    pub fn velocity(&self, t: f64) -> Vector3<f64> {
        let v: Vector3<f64> = self.position_jets(t).map(|j| j.d1).into();
        match &self.mount {
            None => v,
            Some(m) => {
                // d/dt (p_W_F + R_W_F p_F_I) = v + R_W_F (omega_F x p_F_I).
                let r_w_f = self.frame_rotation(t);
                let lever = m.t_f_i.translation.vector;
                m.t_g_w.rotation * (v + r_w_f * self.frame_rate(t).cross(&lever))
            }
        }
    }

    /// Acceleration of `I` in `G` [m/s^2] (without gravity).
    pub fn acceleration(&self, t: f64) -> Vector3<f64> {
        let a: Vector3<f64> = self.position_jets(t).map(|j| j.d2).into();
        match &self.mount {
            None => a,
            Some(m) => {
                let r_w_f = self.frame_rotation(t);
                let lever = m.t_f_i.translation.vector;
                let w = self.frame_rate(t);
                let alpha = self.frame_angular_acceleration(t);
                m.t_g_w.rotation * (a + r_w_f * (alpha.cross(&lever) + w.cross(&w.cross(&lever))))
            }
        }
    }

    /// `omega_I`, angular velocity of `I` relative to `G` in `I` [rad/s]:
    /// `R_G_I(t + h) ~ R_G_I(t) Exp(omega_I h)`.
    pub fn body_rate(&self, t: f64) -> Vector3<f64> {
        match &self.mount {
            None => self.frame_rate(t),
            Some(m) => m
                .t_f_i
                .rotation
                .inverse_transform_vector(&self.frame_rate(t)),
        }
    }

    /// Rotation of the signals' frame (`R_G_I`, or `R_W_F` with a mount).
    fn frame_rotation(&self, t: f64) -> UnitQuaternion<f64> {
        let [roll, pitch, yaw] = self.euler_jets(t);
        UnitQuaternion::from_euler_angles(roll.v, pitch.v, yaw.v)
    }

    /// Body rate of the signals' frame from the ZYX Euler-rate kinematics.
    fn frame_rate(&self, t: f64) -> Vector3<f64> {
        let [roll, pitch, yaw] = self.euler_jets(t);
        let (sr, cr) = roll.v.sin_cos();
        let (sp, cp) = pitch.v.sin_cos();
        Vector3::new(
            roll.d1 - sp * yaw.d1,
            cr * pitch.d1 + sr * cp * yaw.d1,
            -sr * pitch.d1 + cr * cp * yaw.d1,
        )
    }

    /// Time derivative of [`Self::frame_rate`] (body-frame angular acceleration).
    fn frame_angular_acceleration(&self, t: f64) -> Vector3<f64> {
        let [roll, pitch, yaw] = self.euler_jets(t);
        let (sr, cr) = roll.v.sin_cos();
        let (sp, cp) = pitch.v.sin_cos();
        let (r1, p1, y1) = (roll.d1, pitch.d1, yaw.d1);
        Vector3::new(
            roll.d2 - cp * p1 * y1 - sp * yaw.d2,
            -sr * r1 * p1 + cr * pitch.d2 + cr * r1 * cp * y1 - sr * sp * p1 * y1
                + sr * cp * yaw.d2,
            -cr * r1 * p1 - sr * pitch.d2 - sr * r1 * cp * y1 - cr * sp * p1 * y1
                + cr * cp * yaw.d2,
        )
    }

    /// `f_I = R_G_I^T (a_G - g)`, what an ideal accelerometer reads [m/s^2].
    pub fn specific_force(&self, t: f64) -> Vector3<f64> {
        let (r_g_i, _) = self.pose(t);
        r_g_i.inverse_transform_vector(&(self.acceleration(t) - gravity_in_g()))
    }

    fn position_jets(&self, t: f64) -> [Jet; 3] {
        match &self.signals {
            Signals::Sinusoidal { position, .. } => [0, 1, 2].map(|k| position[k].eval(t)),
            Signals::Drive(drive) => drive.position_jets(t),
        }
    }

    fn euler_jets(&self, t: f64) -> [Jet; 3] {
        match &self.signals {
            Signals::Sinusoidal { euler, .. } => [0, 1, 2].map(|k| euler[k].eval(t)),
            Signals::Drive(drive) => drive.euler_jets(t),
        }
    }
}

/// One axis: `sinusoids_per_axis` sinusoids with random frequency and phase;
/// each amplitude gives a derivative amplitude of `derivative_amplitude`,
/// and all are scaled down together if their sum exceeds `cap`.
fn random_signal(
    config: &TrajectoryConfig,
    envelope: SmoothStep,
    rng: &mut impl Rng,
    base: f64,
    derivative_amplitude: f64,
    cap: f64,
) -> EnvelopedSignal {
    let mut sinusoids: Vec<Sinusoid> = (0..config.sinusoids_per_axis)
        .map(|_| {
            let frequency_hz = if config.max_frequency_hz > config.min_frequency_hz {
                rng.gen_range(config.min_frequency_hz..config.max_frequency_hz)
            } else {
                config.min_frequency_hz
            };
            Sinusoid {
                amplitude: derivative_amplitude / (TAU * frequency_hz),
                frequency_hz,
                phase: rng.gen_range(-PI..PI),
            }
        })
        .collect();
    let total: f64 = sinusoids.iter().map(|s| s.amplitude).sum();
    if total > cap {
        for s in &mut sinusoids {
            s.amplitude *= cap / total;
        }
    }
    EnvelopedSignal {
        base,
        sinusoids,
        envelope,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn trajectory(seed: u64) -> Trajectory {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        Trajectory::random(&TrajectoryConfig::default(), &mut rng)
    }

    /// Still, inside the fade-in (envelope product-rule terms) and in full motion;
    /// not exactly at the fade-in ends, where the jerk jumps and central
    /// differences of the acceleration lose an order.
    const TIMES: [f64; 9] = [0.3, 1.01, 1.2, 1.5, 1.98, 2.02, 3.7, 17.25, 55.5];

    #[test]
    fn velocity_and_acceleration_match_finite_differences_of_position() {
        let h = 1e-4;
        for seed in 0..4 {
            let traj = trajectory(seed);
            for t in TIMES {
                let (_, p_minus) = traj.pose(t - h);
                let (_, p_plus) = traj.pose(t + h);
                let v_fd = (p_plus - p_minus) / (2.0 * h);
                assert!((v_fd - traj.velocity(t)).norm() < 1e-6, "seed {seed} t {t}");
                let a_fd = (traj.velocity(t + h) - traj.velocity(t - h)) / (2.0 * h);
                assert!(
                    (a_fd - traj.acceleration(t)).norm() < 1e-5,
                    "seed {seed} t {t}"
                );
            }
        }
    }

    #[test]
    fn body_rate_matches_log_of_relative_rotation() {
        let h = 1e-4;
        for seed in 0..4 {
            let traj = trajectory(seed);
            for t in TIMES {
                let (r_minus, _) = traj.pose(t - h);
                let (r_plus, _) = traj.pose(t + h);
                let omega_fd = (r_minus.inverse() * r_plus).scaled_axis() / (2.0 * h);
                let omega = traj.body_rate(t);
                assert!(
                    (omega_fd - omega).norm() < 1e-6,
                    "seed {seed} t {t}: {omega_fd} vs {omega}"
                );
            }
        }
    }

    #[test]
    fn specific_force_matches_finite_differences_in_the_body_frame() {
        let h = 1e-4;
        let traj = trajectory(9);
        for t in TIMES {
            let (_, p_minus) = traj.pose(t - h);
            let (r, p) = traj.pose(t);
            let (_, p_plus) = traj.pose(t + h);
            let a_fd = (p_plus - 2.0 * p + p_minus) / (h * h);
            let f_fd = r.inverse_transform_vector(&(a_fd - gravity_in_g()));
            assert!((f_fd - traj.specific_force(t)).norm() < 1e-3, "t {t}");
        }
    }

    fn look_at(seed: u64) -> Trajectory {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mount = Mount {
            t_g_w: Isometry3::from_parts(
                Translation3::new(0.3, -0.2, 1.4),
                UnitQuaternion::from_euler_angles(-1.9, 0.1, 0.7),
            ),
            t_f_i: Isometry3::from_parts(
                Translation3::new(0.05, -0.08, 0.03),
                UnitQuaternion::from_euler_angles(1.5, -0.2, 3.0),
            ),
        };
        let look = LookAtConfig {
            distance_m: 0.9,
            max_offset_m: [0.2, 0.15, 0.15],
            max_deviation_rad: [0.15, 0.15, 0.5],
        };
        let config = TrajectoryConfig {
            min_frequency_hz: 0.6,
            max_frequency_hz: 1.6,
            ..TrajectoryConfig::default()
        };
        Trajectory::random_look_at(&config, &look, mount, &mut rng)
    }

    #[test]
    fn look_at_derivatives_match_finite_differences() {
        let h = 1e-4;
        for seed in 0..3 {
            let traj = look_at(seed);
            for t in TIMES {
                let (r_minus, p_minus) = traj.pose(t - h);
                let (r_plus, p_plus) = traj.pose(t + h);
                let v_fd = (p_plus - p_minus) / (2.0 * h);
                assert!((v_fd - traj.velocity(t)).norm() < 1e-6, "seed {seed} t {t}");
                let a_fd = (traj.velocity(t + h) - traj.velocity(t - h)) / (2.0 * h);
                let a = traj.acceleration(t);
                assert!((a_fd - a).norm() < 1e-5, "seed {seed} t {t}: {a_fd} vs {a}");
                let omega_fd = (r_minus.inverse() * r_plus).scaled_axis() / (2.0 * h);
                let omega = traj.body_rate(t);
                assert!((omega_fd - omega).norm() < 1e-6, "seed {seed} t {t}");
            }
        }
    }

    #[test]
    fn look_at_keeps_the_point_near_the_optical_axis() {
        for seed in 0..3 {
            let traj = look_at(seed);
            let m = *traj.mount().unwrap();
            let point_g = m.t_g_w * nalgebra::Point3::new(0.0, 0.0, 0.9);
            let mut worst: f64 = 0.0;
            for k in 0..3000 {
                let t = 0.02 * f64::from(k);
                let t_g_f = traj.isometry(t) * m.t_f_i.inverse();
                let p_f = t_g_f.inverse() * point_g;
                worst = worst.max((p_f.x.hypot(p_f.y) / p_f.z).atan());
            }
            // Independent pan/tilt deviations are capped at 0.15 rad each.
            assert!(worst < 0.3, "seed {seed}: {worst}");
        }
    }

    #[test]
    fn still_at_the_start_then_excited_on_every_axis() {
        let traj = trajectory(1);
        assert!(traj.body_rate(0.5).norm() < 1e-15);
        assert!(traj.velocity(0.99).norm() < 1e-15);
        let f = traj.specific_force(0.5);
        assert!((f.norm() - GRAVITY).abs() < 1e-12);

        let mut max_rate = Vector3::<f64>::zeros();
        let (mut max_speed, mut max_accel) = (0.0_f64, 0.0_f64);
        for k in 0..6000 {
            let t = 2.0 + f64::from(k) * 0.01;
            max_rate = max_rate.zip_map(&traj.body_rate(t), |m, w| m.max(w.abs()));
            max_speed = max_speed.max(traj.velocity(t).norm());
            max_accel = max_accel.max(traj.acceleration(t).norm());
        }
        assert!(
            max_rate.iter().all(|&w| (0.8..3.0).contains(&w)),
            "{max_rate}"
        );
        assert!((0.3..2.0).contains(&max_speed), "{max_speed}");
        assert!((1.0..10.0).contains(&max_accel), "{max_accel}");
    }
}
