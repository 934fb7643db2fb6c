//! Whether the extrinsic steps the filter's health monitor reacted to are real: a
//! calibration assumes one constant extrinsic over the recording, and a step (a knock) is
//! accepted only when it explains the odometry better than that constant does.
//!
//! The health monitor's step detector (a GLR test on the innovations, `estimator::health`)
//! was built for simulated odometry with Gaussian noise. Real odometry carries unmodelled,
//! heavy-tailed errors (PnP poses in fast motion, the IMU's scale and misalignment): on EuRoC
//! `imu_april` it fired eight times, and each reaction (the extrinsic covariance opened by
//! 0.2 deg / 5 mm plus the step estimate's own) threw away what the filter had learnt, so
//! the rotation wandered up to 1.3 deg and ended wherever the last seconds put it. Held
//! constant, the same filter ends within 0.03 deg of every other setting (docs/pose-imu.md).

use msreg_estimator::chi2::{self, Confidence};
use msreg_estimator::{HealthConfig, Scalar};

use super::super::driver::report::{HistoryPoint, PoseImuCalibration};

/// The health monitor of the constant-extrinsic pass: the default with the step detectors
/// unable to fire (no step is worth an alarm), so the filter never opens the extrinsic.
pub(super) fn constant_extrinsic<T: Scalar>() -> HealthConfig<T> {
    HealthConfig {
        min_rotation_step: T::lit(f64::INFINITY),
        min_translation_step: T::lit(f64::INFINITY),
        ..HealthConfig::default()
    }
}

/// Gate of a truncated NIS term: the filter's own default gate.
const GATE: Confidence = Confidence::P999;

/// Confidence at which the steps' better fit must exceed what their extra parameters buy.
const STEP_CONFIDENCE: Confidence = Confidence::P9999;

/// The sum over `history` from `from_s` on of each update's NIS, truncated at its gate: an
/// update the gate rejects counts its threshold, so one wild increment cannot decide.
pub(super) fn truncated_nis(history: &[HistoryPoint], from_s: f64) -> f64 {
    history
        .iter()
        .filter(|h| h.t_s >= from_s)
        .map(|h| h.nis.min(chi2::quantile::<f64>(h.dof, GATE)))
        .sum()
}

/// How much better the steps must explain the odometry (in truncated NIS) to stand: the
/// chi-square quantile of the 3 parameters each step adds.
pub(super) fn step_allowance(steps: usize) -> f64 {
    chi2::quantile::<f64>(3 * steps, STEP_CONFIDENCE)
}

/// The result to report: the `reacting` run (its steps stand) when its truncated NIS after
/// the first step is lower than the `constant` run's by more than [`step_allowance`], else
/// the constant run (whose report lists no events: the steps were refuted).
pub(super) fn judge(
    reacting: PoseImuCalibration,
    constant: PoseImuCalibration,
) -> PoseImuCalibration {
    let Some(first_s) = reacting
        .report
        .events
        .iter()
        .map(|e| e.t_s)
        .min_by(f64::total_cmp)
    else {
        return reacting;
    };
    let with_steps = truncated_nis(&reacting.report.history, first_s);
    let held = truncated_nis(&constant.report.history, first_s);
    if held - with_steps > step_allowance(reacting.report.events.len()) {
        reacting
    } else {
        constant
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(t_s: f64, nis: f64) -> HistoryPoint {
        HistoryPoint {
            t_s,
            rotation_vector: [0.0; 3],
            translation_m: [0.0; 3],
            sigma_rot_deg: [0.0; 3],
            sigma_trans_m: [0.0; 3],
            time_offset_s: 0.0,
            sigma_time_offset_s: 0.0,
            nis,
            dof: 6,
            accepted: true,
        }
    }

    #[test]
    fn truncated_nis_caps_each_update_at_its_gate_and_starts_at_the_step() {
        let gate = chi2::quantile::<f64>(6, GATE);
        let history = [point(1.0, 1e6), point(2.0, 1e6), point(3.0, 4.0)];
        assert!((truncated_nis(&history, 2.0) - (gate + 4.0)).abs() < 1e-9);
        assert!((truncated_nis(&history, 0.0) - (2.0 * gate + 4.0)).abs() < 1e-9);
        assert!(truncated_nis(&history, 4.0).abs() < 1e-12);
    }

    #[test]
    fn the_allowance_grows_with_the_steps() {
        assert!(step_allowance(1) > 20.0 && step_allowance(1) < 22.0);
        assert!(step_allowance(8) > step_allowance(1));
        let constant = constant_extrinsic::<f32>();
        assert!(constant.is_valid());
        assert!(constant.min_rotation_step.is_infinite());
    }
}
