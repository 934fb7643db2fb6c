//! The end of an IMU pipeline's run: the convergence history, the checks that decide convergence
//! (sigmas, NIS, observability) and the report.

use crate::calibrate::convert;
use crate::calibrate::driver::report::{
    EventRecord, HistoryPoint, PoseImuCalibration, PoseImuReport, Timing,
};
use crate::calibrate::init::{self, Standstill};
use crate::calibrate::observability::{self, HeldDirection};
use crate::dataset::PoseRecord;
use msreg_estimator::{
    health::HealthEvent, Ekf, Error as FilterError, PoseImuEkf, RelativePose, Scalar, SensorId,
    SOLE_SENSOR,
};
use nalgebra::Matrix6;

/// Bookkeeping of one run over the recording.
pub(crate) struct Run {
    /// The filter's sensor whose measurements this run books.
    pub(crate) sensor: SensorId,
    pub(crate) start_ns: u64,
    pub(crate) max_interval_ns: u64,
    pub(crate) period_ns: u64,
    pub(crate) previous: Option<PoseRecord>,
    pub(crate) history: Vec<HistoryPoint>,
    pub(crate) events: Vec<EventRecord>,
    /// Measurements skipped, with reasons (report).
    pub(crate) skipped: Vec<String>,
    pub(crate) accepted: usize,
    pub(crate) rejected: usize,
    /// Poses that only anchored the odometry because they were taken at rest.
    pub(crate) at_rest: usize,
    pub(crate) nis_sum: f64,
    pub(crate) nis_dof: usize,
}

impl Run {
    pub(crate) fn new(start_ns: u64, period_ns: u64) -> Self {
        Self {
            sensor: SOLE_SENSOR,
            start_ns,
            max_interval_ns: period_ns.saturating_mul(10),
            period_ns,
            previous: None,
            history: Vec::new(),
            events: Vec::new(),
            skipped: Vec::new(),
            accepted: 0,
            rejected: 0,
            at_rest: 0,
            nis_sum: 0.0,
            nis_dof: 0,
        }
    }

    /// The same run booking sensor `s` of the filter ([`SOLE_SENSOR`] unless the filter has
    /// several).
    pub(crate) fn for_sensor(mut self, s: SensorId) -> Self {
        self.sensor = s;
        self
    }

    pub(crate) fn seconds(&self, stamp_ns: u64) -> f64 {
        stamp_ns.saturating_sub(self.start_ns) as f64 * 1e-9
    }

    pub(crate) fn skip(&mut self, stamp_ns: u64, why: &str) {
        self.skip_measurement("pose0", stamp_ns, why);
    }

    /// Books a measurement of `sensor` that was not fused, with the reason.
    pub(crate) fn skip_measurement(&mut self, sensor: &str, stamp_ns: u64, why: &str) {
        self.skipped
            .push(format!("{sensor} stamp {stamp_ns}: {why}"));
    }

    /// Anchors the odometry at `pose`, taken at rest, instead of fusing its increment.
    pub(crate) fn anchor_at_rest<T: Scalar>(&mut self, ekf: &mut PoseImuEkf<T>, pose: &PoseRecord) {
        self.at_rest += 1;
        self.anchor(ekf, pose);
    }

    /// Starts a new odometry segment at `pose`, fusing nothing.
    pub(crate) fn anchor<T: Scalar>(&mut self, ekf: &mut PoseImuEkf<T>, pose: &PoseRecord) {
        match ekf.anchor(SOLE_SENSOR, pose.stamp_ns) {
            Ok(()) => self.previous = Some(*pose),
            Err(e) => self.skip(pose.stamp_ns, &format!("cannot anchor: {e}")),
        }
    }

    /// Anchors a new odometry segment or fuses the increment from the previous pose.
    pub(crate) fn fuse_pose<T: Scalar>(
        &mut self,
        ekf: &mut PoseImuEkf<T>,
        pose: &PoseRecord,
        sigma_r: f64,
        sigma_t: f64,
    ) {
        let previous = self
            .previous
            .filter(|p| pose.stamp_ns - p.stamp_ns <= self.max_interval_ns);
        let Some(prev) = previous else {
            self.anchor(ekf, pose);
            return;
        };
        // Odometry noise accumulates per increment: an interval spanning several nominal
        // periods (a gap) carries the noise of all of them.
        let periods = ((pose.stamp_ns - prev.stamp_ns) as f64 / self.period_ns as f64)
            .round()
            .max(1.0);
        let scale = periods.sqrt();
        let delta = prev.isometry().inverse() * pose.isometry();
        let meas = RelativePose::with_sigmas(
            prev.stamp_ns,
            pose.stamp_ns,
            convert::pose::<T>(&delta),
            T::lit(sigma_r * scale),
            T::lit(sigma_t * scale),
        );
        match ekf.update_relative_pose(SOLE_SENSOR, &meas) {
            Ok(report) => {
                self.previous = Some(*pose);
                self.record_update(ekf, pose.stamp_ns, &report);
            }
            Err(FilterError::NoAnchor | FilterError::OlderThanWindow) => {
                self.previous = None;
                self.fuse_pose(ekf, pose, sigma_r, sigma_t);
            }
            Err(e) => self.skip(pose.stamp_ns, &format!("{e}")),
        }
    }

    /// Books a relative-pose update of the measurement stamped `stamp_ns`: counts, NIS,
    /// health events and a history point.
    pub(crate) fn record_update<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
        stamp_ns: u64,
        report: &msreg_estimator::UpdateReport<T>,
    ) {
        if report.accepted {
            self.accepted += 1;
        } else if !report.held_out {
            // Held out while a knock candidate was tested: not a gate rejection.
            self.rejected += 1;
        }
        self.nis_sum += report.nis.to_f64();
        self.nis_dof += report.dof;
        if let Some(event) = report.event {
            self.events.push(self.event_record(&event));
        }
        self.history.push(history_point(
            ekf,
            self.sensor,
            self.seconds(stamp_ns),
            (report.nis.to_f64(), report.dof),
            report.accepted,
        ));
    }

    pub(crate) fn event_record<T: Scalar>(&self, event: &HealthEvent<T>) -> EventRecord {
        match *event {
            HealthEvent::RotationStep {
                stamp_ns,
                statistic,
                step,
                ..
            } => EventRecord {
                t_s: self.seconds(stamp_ns),
                kind: "rotation_step",
                statistic: statistic.to_f64(),
                magnitude: step.norm().to_f64(),
            },
            HealthEvent::TranslationStep {
                stamp_ns,
                statistic,
                step,
                ..
            } => EventRecord {
                t_s: self.seconds(stamp_ns),
                kind: "translation_step",
                statistic: statistic.to_f64(),
                magnitude: step.norm().to_f64(),
            },
        }
    }
}

pub(crate) fn history_point<
    T: Scalar,
    const S: usize,
    const C: usize,
    const N: usize,
    const F: usize,
>(
    ekf: &Ekf<T, S, C, N, F>,
    s: SensorId,
    t_s: f64,
    (nis, dof): (f64, usize),
    accepted: bool,
) -> HistoryPoint {
    let x = convert::isometry(&ekf.extrinsic(s));
    let (sr, st) = ekf.extrinsic_sigma(s);
    let rv = x.rotation.scaled_axis();
    HistoryPoint {
        t_s,
        rotation_vector: [rv.x, rv.y, rv.z],
        translation_m: [x.translation.x, x.translation.y, x.translation.z],
        sigma_rot_deg: [0, 1, 2].map(|i| sr[i].to_f64().to_degrees()),
        sigma_trans_m: [0, 1, 2].map(|i| st[i].to_f64()),
        time_offset_s: ekf.time_offset(s).to_f64(),
        sigma_time_offset_s: ekf.time_offset_sigma(s).to_f64(),
        nis,
        dof,
        accepted,
    }
}

/// Largest final 1-sigma rotation (deg) of a converged calibration.
pub(crate) const CONVERGED_SIGMA_ROT_DEG: f64 = 0.5;

/// Largest final 1-sigma translation (m) of a converged calibration.
pub(crate) const CONVERGED_SIGMA_TRANS_M: f64 = 0.02;

pub(crate) fn finish<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &Ekf<T, S, C, N, F>,
    run: Run,
    standstill: Option<&Standstill>,
    rotation_init: &init::RotationInit,
    timing: Timing,
) -> PoseImuCalibration {
    let s = run.sensor;
    let covariance = Matrix6::from_fn(|r, c| ekf.extrinsic_covariance(s)[(r, c)].to_f64());
    let (sr, st) = ekf.extrinsic_sigma(s);
    let mut reasons = Vec::new();
    let max_sr = sr.amax().to_f64().to_degrees();
    let held = ekf.held_translation_axis(s).map(|a| HeldDirection {
        axis: convert::vec3_f64(&a),
        reason: "planar motion (rotation about one axis)".to_string(),
    });
    let translation_cov = covariance.fixed_view::<3, 3>(3, 3).clone_owned();
    let (max_st, worst) =
        observability::largest_sigma_across(&translation_cov, held.as_ref().map(|h| &h.axis));
    if max_sr > CONVERGED_SIGMA_ROT_DEG {
        let axes = observability::axes_above(
            &sr.map(|x| x.to_f64().to_degrees()),
            CONVERGED_SIGMA_ROT_DEG,
        );
        reasons.push(format!(
            "rotation about {axes}: sigma up to {max_sr:.3} deg > {CONVERGED_SIGMA_ROT_DEG} deg: \
             not enough rotation"
        ));
    }
    if max_st > CONVERGED_SIGMA_TRANS_M {
        reasons.push(format!(
            "translation along [{:.2}, {:.2}, {:.2}]: sigma {max_st:.4} m > \
             {CONVERGED_SIGMA_TRANS_M} m: not enough rotation to observe the lever arm",
            worst.x, worst.y, worst.z
        ));
    }
    let total = run.accepted + run.rejected;
    if total == 0 || run.rejected * 10 > total {
        reasons.push(format!(
            "{} of {} relative poses rejected by the gate: odometry noise or time offset \
             mismatched",
            run.rejected, total
        ));
    }
    let mean_nis = run.nis_sum / run.nis_dof.max(1) as f64;
    let rv = rotation_init.rotation.scaled_axis();
    let excitation = ekf.excitation(s).map(|x| x.to_f64());
    let sigma = [sr.x, sr.y, sr.z, st.x, st.y, st.z, ekf.time_offset_sigma(s)].map(|x| x.to_f64());
    let prior = ekf.prior_sigma(s).map(|x| x.to_f64());
    let report = PoseImuReport {
        converged: reasons.is_empty(),
        reasons,
        scalar: core::any::type_name::<T>(),
        standstill_s: standstill.map_or(0.0, |s| run.seconds(s.until_ns)),
        moving_start: String::new(),
        gyro_bias_init: String::new(),
        planar: String::new(),
        observability: observability::table(&sigma, &prior, &translation_cov, held.as_ref()),
        held_axis: held.as_ref().map(|h| [h.axis.x, h.axis.y, h.axis.z]),
        hand_eye_pairs: rotation_init.pairs,
        hand_eye_axis_ratio: rotation_init.axis_ratio,
        hand_eye_rotation_vector: [rv.x, rv.y, rv.z],
        updates_accepted: run.accepted,
        updates_rejected: run.rejected,
        poses_at_rest: run.at_rest,
        poses_skipped: run.skipped,
        mean_nis_per_dof: mean_nis,
        excitation,
        events: run.events,
        timing_s: timing,
        history: run.history,
    };
    PoseImuCalibration {
        t_imu_sensor: convert::isometry(&ekf.extrinsic(s)),
        time_offset_s: ekf.time_offset(s).to_f64(),
        time_offset_sigma_s: ekf.time_offset_sigma(s).to_f64(),
        covariance,
        report,
    }
}
