//! The error-state EKF: IMU propagation, stochastic cloning and measurement updates over a
//! compile-time layout of `S` sensors, `C` clones and `F` static frames
//! (`N = 15 + 7 S + 6 C + 6 F`).
//!
//! Every public method either succeeds or returns an [`Error`] with the filter unchanged:
//! an update checks everything that can fail (gate, positive-definite innovation,
//! finiteness) before it writes anything, and what has to move first (propagation and a new
//! clone; the corners of an image before its gate) is taken back from an undo record, never
//! from a copy of the filter (see `filter/undo.rs`).

use crate::chi2::Confidence;
use crate::health::{HealthConfig, HealthMonitor};
use crate::ids::{FrameId, SensorId};
use crate::lie::Pose;
use crate::propagate::{self, ImuNoise, ImuSample, ImuSignal, Rotations};
use crate::scalar::Scalar;
use crate::state::{imu, Block, CloneState, ImuState, InitialState, Layout, SensorState};
use crate::Error;
use nalgebra::{SMatrix, Vector3};

/// Filter for one pose sensor and an IMU, with the two clones relative poses need.
pub type PoseImuEkf<T> = Ekf<T, 1, 2, 34>;
/// The joint layout (issue 13): an IMU, two sensors (LiDAR 0, camera 1: extrinsic and time
/// offset each), four clones (two per relative-pose sensor: a LiDAR's odometry and a
/// camera's visual odometry on the vehicle) and one static target frame (the board of a
/// joint calibration): `15 + 2 * 7 + 4 * 6 + 6 = 59` error states.
pub type JointEkf<T> = Ekf<T, 2, 4, 59, 1>;
/// The joint layout without the target frame: on-vehicle monitoring (two pose sensors).
pub type MonitorEkf<T> = Ekf<T, 2, 4, 53>;
/// Filter for a camera and an IMU observing one static target (RepErrCal): the target pose
/// is a state, no clones are needed.
pub type CameraImuEkf<T> = Ekf<T, 1, 0, 28, 1>;

/// The sensor of the one-sensor layouts ([`PoseImuEkf`], [`CameraImuEkf`]).
pub const SOLE_SENSOR: SensorId = SensorId::at::<0, 1>();
/// The static target frame of the one-frame layouts ([`CameraImuEkf`], [`JointEkf`]).
pub const TARGET_FRAME: FrameId = FrameId::at::<0, 1>();
/// The LiDAR of the joint layout ([`JointEkf`]; the first pose sensor of [`MonitorEkf`]).
pub const JOINT_LIDAR: SensorId = SensorId::at::<0, 2>();
/// The camera of the joint layout ([`JointEkf`]; the second pose sensor of [`MonitorEkf`]).
pub const JOINT_CAMERA: SensorId = SensorId::at::<1, 2>();

/// Filter tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterConfig<T: Scalar> {
    /// IMU noise densities.
    pub imu_noise: ImuNoise<T>,
    /// Chi-square gate of every update.
    pub gate: Confidence,
    /// Largest accepted spacing of IMU samples (and extrapolation beyond the last one), ns.
    pub max_imu_gap_ns: u64,
    /// Health monitor tuning.
    pub health: HealthConfig<T>,
    /// Zero-velocity update: 1-sigma of "not moving", m/s.
    pub zero_velocity_sigma: T,
    /// How far, ns, a measurement's IMU time `stamp + t_d` may fall behind the filter time
    /// and still be fused, at the filter time. The estimate of `t_d` moves with every
    /// update, so a measurement that was not yet due when an IMU sample was propagated can
    /// be a little behind it one sample later; its `t_d` Jacobian absorbs the difference.
    pub max_late_ns: u64,
    /// Largest factor by which a reprojection update's corner noise may be scaled when the
    /// gate rejects the image at its stated noise: an image with NIS / dof up to this
    /// squared is fused again with its noise scaled by sqrt(NIS / dof) (a frame-level
    /// robust weight; real images carry blur and model errors that vary from frame to
    /// frame). 1 turns it off: the plain gate.
    pub max_noise_scale: T,
    /// Keeps the rotation about gravity unobservable (`filter/yaw_gauge.rs`): for layouts
    /// fed relative poses only (no static frames). Off by default.
    pub constrain_yaw: bool,
    /// How a propagation step evaluates `Exp` and the right Jacobian of its small rotation:
    /// libm's trigonometry (the default, the reference numbers) or the power series
    /// (rounding-level differences; 8,562 fewer instructions per IMU sample on a
    /// Cortex-M4F, whose FPU has no `f64`: docs/estimator.md, "Propagation on the device").
    pub rotations: Rotations,
}

impl<T: Scalar> FilterConfig<T> {
    /// Defaults around the given IMU noise.
    pub fn new(imu_noise: ImuNoise<T>) -> Self {
        Self {
            imu_noise,
            gate: Confidence::P999,
            max_imu_gap_ns: 50_000_000,
            health: HealthConfig::default(),
            zero_velocity_sigma: T::lit(0.01),
            max_late_ns: 1_000_000,
            max_noise_scale: T::one(),
            constrain_yaw: false,
            rotations: Rotations::Trigonometric,
        }
    }
}

/// The error-state EKF with `S` sensors, `C` clone slots and `F` static frames (targets whose
/// pose in G is estimated; none by default).
#[derive(Clone, Debug)]
pub struct Ekf<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize = 0> {
    config: FilterConfig<T>,
    time_ns: u64,
    /// The IMU reading at `time_ns`: a received sample, or interpolated between two.
    imu_now: Option<ImuSample<T>>,
    /// The newest sample, ahead of `time_ns` (the one-sample look-ahead): the signal is known
    /// up to its stamp, so measurements up to there can be fused. `None` until a second
    /// sample has arrived.
    imu_ahead: Option<ImuSample<T>>,
    /// The last two samples received before `imu_ahead`, older first: the interval under way
    /// starts at the second; the first gives the signal's curvature ([`ImuSignal`]).
    imu_base: [Option<ImuSample<T>>; 2],
    /// Spacing of the last two samples received, ns (0 before the second): the period one
    /// reading's white noise refers to.
    imu_period_ns: u64,
    imu: ImuState<T>,
    sensors: [SensorState<T>; S],
    prior_sigma: [[T; 7]; S],
    clones: [Option<CloneState<T>>; C],
    anchors: [Option<usize>; S],
    /// `T_G_F` of each static frame, once initialised (see [`Ekf::init_frame`]).
    frames: [Option<Pose<T>>; F],
    /// Covariance; its IMU-to-rest block `P_IX` lags by `pending_transition`.
    cov: SMatrix<T, N, N>,
    /// Product of the IMU transitions since `P_IX` was last brought up to date: static
    /// blocks only change through it, so it is applied once per update, not per sample.
    pending_transition: SMatrix<T, 15, 15>,
    health: HealthMonitor<T, S>,
    /// Per sensor, a direction of the extrinsic translation held at its prior (see
    /// [`Ekf::hold_translation_axis`]).
    held_translation: [Option<Vector3<T>>; S],
    /// The IMU part of the yaw direction as propagated (`filter/yaw_gauge.rs`).
    yaw_chain: yaw_gauge::YawDirection<T>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    const LAYOUT_OK: () = assert!(
        N == Layout::<S, C>::dim_with_frames(F),
        "N must be 15 + 7 S + 6 C + 6 F"
    );

    /// A filter at the prior `init`; time starts at the first IMU sample.
    pub fn new(config: &FilterConfig<T>, init: &InitialState<T, S>) -> Result<Self, Error> {
        let () = Self::LAYOUT_OK;
        if !init.is_valid()
            || !config.imu_noise.is_valid()
            || !config.health.is_valid()
            || (config.constrain_yaw && F > 0)
        {
            return Err(Error::InvalidConfig);
        }
        let mut cov = SMatrix::<T, N, N>::zeros();
        let mut set = |b: Block, sigma: T| {
            for i in b.idx..b.end() {
                cov[(i, i)] = sigma * sigma;
            }
        };
        set(imu::ORIENTATION, init.sigma_orientation);
        set(imu::POSITION, init.sigma_position);
        set(imu::VELOCITY, init.sigma_velocity);
        set(imu::GYRO_BIAS, init.sigma_gyro_bias);
        set(imu::ACCEL_BIAS, init.sigma_accel_bias);
        let mut prior_sigma = [[T::zero(); 7]; S];
        for (s, p) in SensorId::all::<S>().into_iter().zip(&init.sensors) {
            set(Layout::<S, C>::extrinsic_rotation(s), p.sigma_rotation);
            set(
                Layout::<S, C>::extrinsic_translation(s),
                p.sigma_translation,
            );
            set(Layout::<S, C>::time_offset(s), p.sigma_time_offset);
            let r = p.sigma_rotation;
            let t = p.sigma_translation;
            prior_sigma[s.index()] = [r, r, r, t, t, t, p.sigma_time_offset];
        }
        Ok(Self {
            config: *config,
            time_ns: 0,
            imu_now: None,
            imu_ahead: None,
            imu_base: [None; 2],
            imu_period_ns: 0,
            imu: init.imu,
            sensors: core::array::from_fn(|s| init.sensors[s].state),
            prior_sigma,
            clones: [None; C],
            anchors: [None; S],
            frames: [None; F],
            cov,
            pending_transition: SMatrix::identity(),
            health: HealthMonitor::new(config.health),
            held_translation: [None; S],
            yaw_chain: if config.constrain_yaw {
                yaw_gauge::yaw_direction(&init.imu)
            } else {
                [Vector3::zeros(); 3]
            },
        })
    }

    // ----- ids ---------------------------------------------------------------------------

    /// The id of sensor `index` of this layout; [`Error::UnknownSensor`] unless `index < S`.
    pub const fn sensor_id(index: usize) -> Result<SensorId, Error> {
        SensorId::new::<S>(index)
    }

    /// The id of static frame `index` of this layout; [`Error::UnknownFrame`] unless
    /// `index < F`.
    pub const fn frame_id(index: usize) -> Result<FrameId, Error> {
        FrameId::new::<F>(index)
    }

    /// The ids of every sensor of this layout, in order.
    pub fn sensor_ids() -> [SensorId; S] {
        SensorId::all::<S>()
    }

    // ----- read access -------------------------------------------------------------------

    /// Filter time, ns (IMU clock). Zero before the first IMU sample.
    pub fn time_ns(&self) -> u64 {
        self.time_ns
    }

    /// Current IMU state.
    pub fn imu(&self) -> &ImuState<T> {
        &self.imu
    }

    /// Calibration state of sensor `s`.
    pub fn sensor(&self, s: SensorId) -> Option<&SensorState<T>> {
        self.sensors.get(s.index())
    }

    /// Extrinsic `T_I_S` of sensor `s` (identity for an unknown sensor).
    pub fn extrinsic(&self, s: SensorId) -> Pose<T> {
        self.sensor(s).map(|x| x.extrinsic).unwrap_or_default()
    }

    /// Time offset `t_d` of sensor `s`, seconds.
    pub fn time_offset(&self, s: SensorId) -> T {
        self.sensor(s).map(|x| x.time_offset).unwrap_or_default()
    }

    /// 1-sigma of the extrinsic of sensor `s`: (rotation axes, rad; translation, m).
    pub fn extrinsic_sigma(&self, s: SensorId) -> (Vector3<T>, Vector3<T>) {
        if s.checked(S).is_err() {
            return (Vector3::zeros(), Vector3::zeros());
        }
        let r = Layout::<S, C>::extrinsic_rotation(s).idx;
        let t = Layout::<S, C>::extrinsic_translation(s).idx;
        let sd = |i: usize| self.cov[(i, i)].max(T::zero()).sqrt();
        (
            Vector3::new(sd(r), sd(r + 1), sd(r + 2)),
            Vector3::new(sd(t), sd(t + 1), sd(t + 2)),
        )
    }

    /// 1-sigma of the time offset of sensor `s`, seconds.
    pub fn time_offset_sigma(&self, s: SensorId) -> T {
        if s.checked(S).is_err() {
            return T::zero();
        }
        let i = Layout::<S, C>::time_offset(s).idx;
        self.cov[(i, i)].max(T::zero()).sqrt()
    }

    /// 6x6 covariance of the extrinsic of sensor `s` (`[rotation; translation]`).
    pub fn extrinsic_covariance(&self, s: SensorId) -> SMatrix<T, 6, 6> {
        if s.checked(S).is_err() {
            return SMatrix::zeros();
        }
        let b = Layout::<S, C>::extrinsic(s).idx;
        self.cov.fixed_view::<6, 6>(b, b).clone_owned()
    }

    /// Prior 1-sigma of sensor `s` (rotation x, y, z in rad, translation x, y, z in m,
    /// time offset in s), as the filter was started; zeros for an unknown sensor.
    pub fn prior_sigma(&self, s: SensorId) -> [T; 7] {
        self.prior_sigma
            .get(s.index())
            .copied()
            .unwrap_or([T::zero(); 7])
    }

    /// Per-DoF excitation of sensor `s`: `1 - sigma / sigma_prior` for rotation x, y, z,
    /// translation x, y, z and time offset (0 = nothing learned, -> 1 = well observed).
    pub fn excitation(&self, s: SensorId) -> [T; 7] {
        let mut out = [T::zero(); 7];
        let Ok(i) = s.checked(S) else {
            return out;
        };
        let base = Layout::<S, C>::extrinsic_rotation(s).idx;
        for (k, o) in out.iter_mut().enumerate() {
            let prior = self.prior_sigma[i][k];
            if prior > T::zero() {
                let sd = self.cov[(base + k, base + k)].max(T::zero()).sqrt();
                *o = (T::one() - sd / prior).max(T::zero());
            }
        }
        out
    }

    /// The whole error-state covariance (with the IMU cross-covariances brought up to date).
    pub fn covariance(&self) -> SMatrix<T, N, N> {
        let mut cov = self.cov;
        Self::apply_pending(&mut cov, &self.pending_transition);
        cov
    }

    /// `P_IX <- Phi_acc P_IX` for every column of the static and clone blocks.
    fn apply_pending(cov: &mut SMatrix<T, N, N>, phi: &SMatrix<T, 15, 15>) {
        for j in imu::DIM..N {
            let col = propagate::transition_mul(phi, &cov.fixed_view::<15, 1>(0, j).clone_owned());
            cov.fixed_view_mut::<15, 1>(0, j).copy_from(&col);
            cov.fixed_view_mut::<1, 15>(j, 0)
                .copy_from(&col.transpose());
        }
    }

    /// Brings `P_IX` up to date (before anything reads or changes it).
    fn flush_transition(&mut self) {
        if self.pending_transition != SMatrix::<T, 15, 15>::identity() {
            Self::apply_pending(&mut self.cov, &self.pending_transition);
            self.pending_transition = SMatrix::identity();
        }
    }

    /// The health monitor.
    pub fn health(&self) -> &HealthMonitor<T, S> {
        &self.health
    }

    /// The configuration.
    pub fn config(&self) -> &FilterConfig<T> {
        &self.config
    }

    // ----- propagation -------------------------------------------------------------------

    /// Feeds one IMU sample (an instantaneous reading at its stamp). The filter keeps it as its
    /// look-ahead and propagates to the previous sample's stamp, over the signal through the
    /// last three readings ([`ImuSignal`]): after sample `k + 1` the filter stands at `t_k` and any
    /// measurement with an IMU time up to `t_k+1` can be fused ([`Ekf::is_due`]). The first
    /// sample only sets the filter time.
    pub fn propagate(&mut self, sample: &ImuSample<T>) -> Result<(), Error> {
        sample.validate()?;
        let Some(now) = self.imu_now else {
            self.time_ns = sample.stamp_ns;
            self.imu_now = Some(*sample);
            self.imu_base = [None, Some(*sample)];
            return Ok(());
        };
        let newest = self.imu_ahead.unwrap_or(now);
        if sample.stamp_ns <= newest.stamp_ns {
            return Err(Error::TimeWentBackwards {
                filter_ns: newest.stamp_ns,
                stamp_ns: sample.stamp_ns,
            });
        }
        let gap = sample.stamp_ns - newest.stamp_ns;
        if gap > self.config.max_imu_gap_ns {
            return Err(Error::ImuGap { gap_ns: gap });
        }
        if let Some(ahead) = self.imu_ahead {
            self.advance_to(ahead.stamp_ns)?;
            self.imu_base = [self.imu_base[1], Some(ahead)];
        }
        self.imu_ahead = Some(*sample);
        self.imu_period_ns = gap;
        Ok(())
    }

    /// Spacing of the last two IMU samples, ns: the period one reading's white noise refers
    /// to (the stream's own, no rate is assumed). `None` before the second sample, when a
    /// zero-velocity update cannot run yet.
    pub fn imu_period_ns(&self) -> Option<u64> {
        (self.imu_period_ns > 0).then_some(self.imu_period_ns)
    }

    /// The newest IMU stamp received, ns: measurements whose IMU time is at or before it can
    /// be fused. `None` before the first sample.
    pub fn imu_horizon_ns(&self) -> Option<u64> {
        self.imu_ahead.or(self.imu_now).map(|s| s.stamp_ns)
    }

    /// IMU time `stamp + t_d` of sensor `s`'s measurement stamped `stamp_ns` (sensor clock),
    /// with the current time-offset estimate. This is the one rule for "when did this
    /// measurement happen on the IMU clock" that every pipeline and the firmware use.
    pub fn imu_time(&self, s: SensorId, stamp_ns: u64) -> Result<u64, Error> {
        let sensor = self.sensor(s).ok_or(Error::UnknownSensor)?;
        // Offset rounded to ns and added in integer space: stamps near 1.7e18 ns have no
        // sub-microsecond resolution as floats.
        let td = libm::round(sensor.time_offset.to_f64() * 1e9) as i64;
        Ok(if td >= 0 {
            stamp_ns.saturating_add(td as u64)
        } else {
            stamp_ns.saturating_sub(td.unsigned_abs())
        })
    }

    /// True when sensor `s`'s measurement stamped `stamp_ns` can be fused now: its IMU time is
    /// at or before the newest IMU sample. Feed IMU samples until it is, then fuse.
    pub fn is_due(&self, s: SensorId, stamp_ns: u64) -> bool {
        match (self.imu_time(s, stamp_ns), self.imu_horizon_ns()) {
            (Ok(t), Some(h)) => t <= h,
            _ => false,
        }
    }

    /// The nominal IMU state the filter will have at `t_ns` (between the filter time and the
    /// newest sample), without changing the filter: e.g. the pose at a LiDAR scan's end.
    pub fn predict_imu(&self, t_ns: u64) -> Result<ImuState<T>, Error> {
        if t_ns == self.time_ns {
            return Ok(self.imu);
        }
        Ok(self.step_to(t_ns)?.0.state)
    }

    /// The propagation step from the filter time to `t_ns` and the reading at `t_ns`. Out of
    /// line: the step's temporaries are popped before the covariance product.
    #[inline(never)]
    fn step_to(&self, t_ns: u64) -> Result<(propagate::ImuStep<T>, ImuSample<T>), Error> {
        let now = self.imu_now.ok_or(Error::NotInitialized)?;
        if t_ns < self.time_ns {
            return Err(Error::TimeWentBackwards {
                filter_ns: self.time_ns,
                stamp_ns: t_ns,
            });
        }
        let ahead = self
            .imu_ahead
            .filter(|a| t_ns <= a.stamp_ns)
            .ok_or(Error::NotYetDue {
                imu_time_ns: t_ns,
                horizon_ns: self.imu_horizon_ns().unwrap_or(self.time_ns),
            })?;
        let start = self.imu_base[1].unwrap_or(now);
        let signal = ImuSignal::new(self.imu_base[0].as_ref(), &start, &ahead);
        let interval = signal.interval(self.time_ns, t_ns);
        let step = propagate::step_with(
            &self.imu,
            &interval,
            &self.config.imu_noise,
            self.config.rotations,
        );
        Ok((step, signal.at(t_ns)))
    }

    /// Propagates state and covariance to `t_ns` (at most the newest sample's stamp) over the
    /// interpolated readings. Only the IMU block changes now, `P_II <- Phi P_II Phi^T + Q`
    /// with the structured product; `P_IX <- Phi P_IX` is deferred by accumulating `Phi` (see
    /// `flush_transition`).
    fn advance_to(&mut self, t_ns: u64) -> Result<(), Error> {
        if self.imu_now.is_none() {
            return Err(Error::NotInitialized);
        }
        if t_ns == self.time_ns {
            return Ok(());
        }
        let (mut step, end) = self.step_to(t_ns)?;
        let chain = if self.config.constrain_yaw {
            let to = yaw_gauge::yaw_direction(&step.state);
            yaw_gauge::constrain_transition(&mut step.transition, &self.yaw_chain, &to)
        } else {
            self.yaw_chain
        };
        let new_ii = Self::propagated_imu_block(&self.cov, &step.transition, &step.noise);
        let pending = propagate::transition_compose(&step.transition, &self.pending_transition);
        let finite = step.state.is_finite()
            && propagate::all_finite(new_ii.as_slice())
            && propagate::all_finite(pending.as_slice());
        if !finite {
            return Err(Error::DivergentUpdate);
        }
        self.cov.fixed_view_mut::<15, 15>(0, 0).copy_from(&new_ii);
        self.pending_transition = pending;
        self.imu = step.state;
        self.yaw_chain = chain;
        self.imu_now = Some(end);
        self.time_ns = t_ns;
        Ok(())
    }

    /// `Phi P_II Phi^T + Q` ([`propagate::covariance_step`]) for the covariance's IMU block.
    /// Out of line, so that its 15 x 15 temporaries are popped before an update that follows
    /// a propagation.
    #[inline(never)]
    fn propagated_imu_block(
        cov: &SMatrix<T, N, N>,
        phi: &SMatrix<T, 15, 15>,
        noise: &SMatrix<T, 15, 15>,
    ) -> SMatrix<T, 15, 15> {
        let p_ii = cov.fixed_view::<15, 15>(0, 0).clone_owned();
        propagate::covariance_step(phi, &p_ii, noise)
    }
}

mod clones;
mod frame_relative;
#[cfg(test)]
mod frame_relative_tests;
mod frames;
mod fuse;
mod gauge;
#[cfg(test)]
mod gauge_tests;
mod holds;
#[cfg(test)]
mod joint_tests;
mod plane;
mod reprojection;
#[cfg(test)]
mod tests;
mod undo;
mod yaw_gauge;
