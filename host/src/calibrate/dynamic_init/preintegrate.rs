//! IMU pre-integration between two instants with instantaneous samples (EuRoC / Kalibr /
//! OpenVINS convention): each sample is the rate and specific force at its stamp, the signal
//! between two samples is their linear interpolation, and each sub-interval is integrated
//! with the mean of its two bounding samples (VINS-Mono's mid-point rule). The window ends
//! are linearly interpolated between the samples around them.

use msreg_estimator::lie;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::dataset::ImuRecord;

/// The IMU motion between `t_a` and `t_b`, in the IMU frame at `t_a`, with the accelerometer
/// bias held at the value it was integrated with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preintegrated {
    /// `t_b - t_a`, s.
    pub dt: f64,
    /// `R_Ia_Ib`.
    pub delta_r: UnitQuaternion<f64>,
    /// `int R_Ia_I(t) f(t) dt`, m/s (no gravity).
    pub delta_v: Vector3<f64>,
    /// `int int R_Ia_I(t) f(t) dt^2`, m (no gravity).
    pub delta_p: Vector3<f64>,
    /// `d delta_v / d b_a` (exact: the increments are linear in the accelerometer bias).
    pub dv_dba: Matrix3<f64>,
    /// `d delta_p / d b_a`.
    pub dp_dba: Matrix3<f64>,
}

/// An IMU record with its time in seconds on a common origin.
#[derive(Debug, Clone, Copy)]
struct Knot {
    t: f64,
    gyro: Vector3<f64>,
    accel: Vector3<f64>,
}

/// The IMU stream with its stamps as seconds after `origin_ns`.
#[derive(Debug, Clone, Copy)]
pub struct ImuSeries<'a> {
    /// Samples, strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// Stamp that is time zero, ns.
    pub origin_ns: u64,
}

impl ImuSeries<'_> {
    /// Time of sample `k`, s after the origin.
    pub fn time(&self, k: usize) -> f64 {
        seconds_between(self.origin_ns, self.imu[k].stamp_ns)
    }

    /// First and last sample time, s; `None` without samples.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((self.time(0), self.time(self.imu.len().checked_sub(1)?)))
    }

    /// The linear interpolation of the samples at `t`; `None` outside the data.
    fn at(&self, t: f64) -> Option<Knot> {
        let (first, last) = self.span()?;
        if !(first..=last).contains(&t) {
            return None;
        }
        let k = self
            .imu
            .partition_point(|r| seconds_between(self.origin_ns, r.stamp_ns) <= t);
        let (a, b) = (k.checked_sub(1)?, k.min(self.imu.len() - 1));
        let (ta, tb) = (self.time(a), self.time(b));
        let s = if tb > ta { (t - ta) / (tb - ta) } else { 0.0 };
        let (ra, rb) = (&self.imu[a], &self.imu[b]);
        Some(Knot {
            t,
            gyro: ra.gyro.lerp(&rb.gyro, s),
            accel: ra.accel.lerp(&rb.accel, s),
        })
    }

    /// Pre-integrates from `t_a` to `t_b` (s after the origin) with the biases removed;
    /// `None` when the interval is empty or leaves the IMU data.
    pub fn preintegrate(
        &self,
        t_a: f64,
        t_b: f64,
        gyro_bias: &Vector3<f64>,
        accel_bias: &Vector3<f64>,
    ) -> Option<Preintegrated> {
        if t_b <= t_a {
            return None;
        }
        let start = self.at(t_a)?;
        let end = self.at(t_b)?;
        let first_inside = self
            .imu
            .partition_point(|r| seconds_between(self.origin_ns, r.stamp_ns) <= t_a);
        let inside = (first_inside..self.imu.len())
            .map(|k| Knot {
                t: self.time(k),
                gyro: self.imu[k].gyro,
                accel: self.imu[k].accel,
            })
            .take_while(|knot| knot.t < t_b);
        let mut acc = Accumulator::new(t_b - t_a);
        let mut previous = start;
        for knot in inside.chain(std::iter::once(end)) {
            acc.step(&previous, &knot, gyro_bias, accel_bias);
            previous = knot;
        }
        Some(acc.result)
    }
}

/// `to - from` in seconds, exact for stamps of any size (integer difference first).
pub fn seconds_between(from_ns: u64, to_ns: u64) -> f64 {
    (i128::from(to_ns) - i128::from(from_ns)) as f64 * 1e-9
}

struct Accumulator {
    rotation: UnitQuaternion<f64>,
    result: Preintegrated,
}

impl Accumulator {
    fn new(dt: f64) -> Self {
        Self {
            rotation: UnitQuaternion::identity(),
            result: Preintegrated {
                dt,
                delta_r: UnitQuaternion::identity(),
                delta_v: Vector3::zeros(),
                delta_p: Vector3::zeros(),
                dv_dba: Matrix3::zeros(),
                dp_dba: Matrix3::zeros(),
            },
        }
    }

    /// One sub-interval `[a.t, b.t]`: rotation with the mean rate, velocity and position
    /// with the mean of the two specific forces rotated into the start frame.
    fn step(&mut self, a: &Knot, b: &Knot, gyro_bias: &Vector3<f64>, accel_bias: &Vector3<f64>) {
        let h = b.t - a.t;
        if h <= 0.0 {
            return;
        }
        let r = &mut self.result;
        let rotation_a = self.rotation;
        let omega = 0.5 * (a.gyro + b.gyro) - gyro_bias;
        let rotation_b = rotation_a * lie::exp(&(omega * h));
        let (ma, mb) = (
            rotation_a.to_rotation_matrix(),
            rotation_b.to_rotation_matrix(),
        );
        let mean_rotation = 0.5 * (ma.matrix() + mb.matrix());
        let accel = 0.5 * (ma * (a.accel - accel_bias) + mb * (b.accel - accel_bias));
        r.delta_p += r.delta_v * h + 0.5 * accel * h * h;
        r.delta_v += accel * h;
        r.dp_dba += r.dv_dba * h - 0.5 * mean_rotation * h * h;
        r.dv_dba -= mean_rotation * h;
        self.rotation = rotation_b;
        r.delta_r = rotation_b;
    }
}
