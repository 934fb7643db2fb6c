//! A car-like planar drive: a vehicle on a level plane following a smooth figure-eight loop
//! with lane-change wiggles, its IMU at the rear-axle centre with `x` forward, `y` left, `z`
//! up. Speed 3-15 m/s, yaw rate up to about 0.5 rad/s.
//!
//! The ground track `(x(t), y(t))` is a sum of sinusoids (`a sin(w t + phi)` along the loop's
//! long axis, `b sin(2 w t + 2 phi)` across it, plus wiggles), rotated to a random heading.
//! The vehicle points along its velocity (no side slip): `yaw = atan2(y', x')`,
//! `yaw' = (x' y'' - y' x'') / s^2`. The suspension rolls it outwards in turns and pitches
//! it nose-down when braking, proportional to the lateral and longitudinal accelerations
//! `a_lat = (x' y'' - y' x'') / s`, `a_lon = (x' x'' + y' y'') / s` (+-2 deg), plus small
//! road bumps; their rates use the track's third derivative, so `body_rate` and
//! `specific_force` stay exact. The second derivatives of roll and pitch (only needed under
//! a [`super::trajectory::Mount`], which a drive never has) are not provided (NaN).

use std::f64::consts::{PI, TAU};

use rand::Rng;

use super::signal::{Jet, Sinusoid};

/// Shape of the random drive.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveConfig {
    /// Range of the figure-eight's period, s.
    pub loop_period_s: (f64, f64),
    /// Speed along the loop's long axis at its centre crossing, m/s.
    pub long_speed_m_s: f64,
    /// Speed across it at the crossing, m/s.
    pub cross_speed_m_s: f64,
    /// Lane-change wiggles: count, amplitude (m) and frequency range (Hz).
    pub wiggles: usize,
    /// Amplitude of each wiggle, m.
    pub wiggle_amplitude_m: f64,
    /// Frequency range of the wiggles, Hz.
    pub wiggle_frequency_hz: (f64, f64),
    /// Roll per lateral and pitch per longitudinal acceleration, rad per m/s^2.
    pub suspension_rad_per_m_s2: f64,
    /// Amplitude of the road bumps on roll and pitch (each), rad.
    pub bump_amplitude_rad: f64,
    /// Frequency range of the bumps, Hz.
    pub bump_frequency_hz: (f64, f64),
    /// Height of the IMU above the plane, m.
    pub height_m: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            loop_period_s: (38.0, 50.0),
            long_speed_m_s: 10.0,
            cross_speed_m_s: 7.0,
            wiggles: 2,
            wiggle_amplitude_m: 0.4,
            wiggle_frequency_hz: (0.08, 0.18),
            suspension_rad_per_m_s2: 0.45f64.to_radians(),
            bump_amplitude_rad: 0.15f64.to_radians(),
            bump_frequency_hz: (0.8, 2.0),
            height_m: 0.5,
        }
    }
}

impl DriveConfig {
    /// A calibration manoeuvre rather than a commute: a clean figure-eight in a parking lot,
    /// about 46 x 19 m, at 3.8-7.8 m/s, with no lane changes. Its tightest turn has a radius
    /// of 5.3 m or more (a car's turning circle; 5.7-6.1 m measured on seeds 0-4) and at most
    /// about 2.7 m/s^2 of lateral acceleration (2.4-2.6 measured), so the suspension rolls it
    /// by up to about 1.5 deg. It turns at 0.37-0.44 rad/s rms (0.39-0.42 measured) against
    /// the default drive's 0.20-0.26 (wiggles aside), and the information about the
    /// mounting's roll and the lever arm across the turn axis grows with the square of that
    /// rate (docs/planar.md, "Meeting the bounds: a calibration figure-eight").
    pub fn figure_eight() -> Self {
        Self {
            loop_period_s: (24.0, 28.0),
            long_speed_m_s: 6.0,
            cross_speed_m_s: 5.0,
            wiggles: 0,
            ..Self::default()
        }
    }
}

/// A sum of sinusoids with four derivatives.
#[derive(Debug, Clone, PartialEq, Default)]
struct SinSum(Vec<Sinusoid>);

impl SinSum {
    /// Value and first three derivatives at `t`.
    fn eval(&self, t: f64) -> [f64; 4] {
        self.0.iter().fold([0.0; 4], |mut acc, s| {
            let w = TAU * s.frequency_hz;
            let (sn, cs) = (w * t + s.phase).sin_cos();
            let a = s.amplitude;
            acc[0] += a * sn;
            acc[1] += a * w * cs;
            acc[2] -= a * w * w * sn;
            acc[3] -= a * w * w * w * cs;
            acc
        })
    }
}

/// The drive's signals (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Drive {
    x: SinSum,
    y: SinSum,
    roll_bumps: SinSum,
    pitch_bumps: SinSum,
    suspension: f64,
    height: f64,
}

fn random_sinusoids(
    rng: &mut impl Rng,
    count: usize,
    amplitude: f64,
    (lo, hi): (f64, f64),
) -> Vec<Sinusoid> {
    (0..count)
        .map(|_| Sinusoid {
            amplitude,
            frequency_hz: if hi > lo { rng.gen_range(lo..hi) } else { lo },
            phase: rng.gen_range(-PI..PI),
        })
        .collect()
}

impl Drive {
    /// A random drive with the shape of `config`.
    pub fn random(config: &DriveConfig, rng: &mut impl Rng) -> Self {
        let (lo, hi) = config.loop_period_s;
        let period = if hi > lo { rng.gen_range(lo..hi) } else { lo };
        let w = TAU / period;
        let phase = rng.gen_range(-PI..PI);
        let heading = rng.gen_range(-PI..PI);
        let turn = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        // Along: a sin(w t + phi), a w = long speed; across: b sin(2 w t + 2 phi), 2 b w = cross.
        let along = Sinusoid {
            amplitude: config.long_speed_m_s / w,
            frequency_hz: 1.0 / period,
            phase,
        };
        let across = Sinusoid {
            amplitude: turn * config.cross_speed_m_s / (2.0 * w),
            frequency_hz: 2.0 / period,
            phase: 2.0 * phase,
        };
        let wiggles = random_sinusoids(
            rng,
            config.wiggles,
            config.wiggle_amplitude_m,
            config.wiggle_frequency_hz,
        );
        let (c, s) = (heading.cos(), heading.sin());
        let rotate = |sin: &Sinusoid, k: f64| Sinusoid {
            amplitude: sin.amplitude * k,
            ..*sin
        };
        // Rotating the track by `heading`: x = c X - s Y, y = s X + c Y.
        let mut x = vec![rotate(&along, c), rotate(&across, -s)];
        let mut y = vec![rotate(&along, s), rotate(&across, c)];
        x.extend(wiggles.iter().map(|wg| rotate(wg, -s)));
        y.extend(wiggles.iter().map(|wg| rotate(wg, c)));
        let bumps = |rng: &mut _| {
            SinSum(random_sinusoids(
                rng,
                2,
                config.bump_amplitude_rad,
                config.bump_frequency_hz,
            ))
        };
        Self {
            x: SinSum(x),
            y: SinSum(y),
            roll_bumps: bumps(rng),
            pitch_bumps: bumps(rng),
            suspension: config.suspension_rad_per_m_s2,
            height: config.height_m,
        }
    }

    /// Position of the IMU (x, y, z) with two derivatives.
    pub fn position_jets(&self, t: f64) -> [Jet; 3] {
        let [x, y] = [&self.x, &self.y].map(|s| {
            let d = s.eval(t);
            Jet {
                v: d[0],
                d1: d[1],
                d2: d[2],
            }
        });
        [x, y, Jet::constant(self.height)]
    }

    /// Roll, pitch, yaw (ZYX) with their first derivatives (second: NaN, see module docs).
    pub fn euler_jets(&self, t: f64) -> [Jet; 3] {
        let (x, y) = (self.x.eval(t), self.y.eval(t));
        let s2 = x[1] * x[1] + y[1] * y[1];
        let s = s2.sqrt();
        let cross = x[1] * y[2] - y[1] * x[2];
        let dot = x[1] * x[2] + y[1] * y[2];
        let (a_lat, a_lon) = (cross / s, dot / s);
        // d/dt cross = x' y''' - y' x'''; d/dt dot = x''^2 + x' x''' + y''^2 + y' y'''; s' = a_lon.
        let d_cross = x[1] * y[3] - y[1] * x[3];
        let d_dot = x[2] * x[2] + x[1] * x[3] + y[2] * y[2] + y[1] * y[3];
        let d_lat = (d_cross * s - cross * a_lon) / s2;
        let d_lon = (d_dot * s - dot * a_lon) / s2;
        let (rb, pb) = (self.roll_bumps.eval(t), self.pitch_bumps.eval(t));
        let k = self.suspension;
        [
            Jet {
                v: k * a_lat + rb[0],
                d1: k * d_lat + rb[1],
                d2: f64::NAN,
            },
            Jet {
                v: -k * a_lon + pb[0],
                d1: -k * d_lon + pb[1],
                d2: f64::NAN,
            },
            Jet {
                v: y[1].atan2(x[1]),
                d1: cross / s2,
                d2: f64::NAN,
            },
        ]
    }
}
