//! The monitor's verdict for an operator: which sensor moved, about which of its axes, by how
//! much (with its uncertainty), since when, and what to do; or that every sensor is within
//! a stated distance of the calibration of record.
//!
//! The change of a sensor is its final estimate against the calibration of record: the
//! rotation `log(R_record^T R_final)` (a right perturbation, so in the sensor's own axes, as
//! the filter's covariance and the detectors' steps are) and the translation difference in the
//! IMU frame. Its 1-sigma along the change's direction counts both the final covariance and the
//! record's sigmas (their errors are independent once a detected step has re-opened the
//! sensor's covariance; without one, this overstates the spread of the difference).

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use super::{MonitorReport, SensorReport};

/// Names of a sensor's own axes, by index (`x (roll)`, ...).
pub const AXIS_NAMES: [&str; 3] = ["x (roll)", "y (pitch)", "z (yaw)"];

/// A sensor's rotation since the calibration of record.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct RotationChange {
    /// Rotation vector in the sensor's frame, deg.
    pub vector_deg: [f64; 3],
    /// Its angle, deg.
    pub angle_deg: f64,
    /// 1-sigma of the angle (along the rotation's axis), deg.
    pub sigma_deg: f64,
    /// Unit axis in the sensor's frame (`[0, 0, 0]` when the angle is zero).
    pub axis: [f64; 3],
    /// Index of the axis' largest component (0 = x, 1 = y, 2 = z).
    pub main_axis: usize,
}

/// A sensor's translation since the calibration of record.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct TranslationChange {
    /// Final minus record, IMU frame, mm.
    pub vector_mm: [f64; 3],
    /// Its length, mm.
    pub length_mm: f64,
    /// 1-sigma of the length (along the change's direction), mm.
    pub sigma_mm: f64,
}

impl TranslationChange {
    /// More than 3 sigma: the lever arm itself moved.
    pub fn is_significant(&self) -> bool {
        self.length_mm > 3.0 * self.sigma_mm
    }
}

/// One sensor's verdict.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct SensorVerdict {
    /// `pose0`, `pose1`, ...
    pub sensor: &'static str,
    /// A step alarm was raised on the sensor: its mounting changed.
    pub moved: bool,
    /// Time of its first alarm, s after the first IMU sample.
    pub flagged_at_s: Option<f64>,
    /// When it moved, s: the knock candidate's increment that the alarm confirmed (the
    /// knock's own increment, docs/monitor.md); the alarm time when the step detector alone
    /// raised it.
    pub since_s: Option<f64>,
    /// Rotation since the record.
    pub rotation: RotationChange,
    /// Translation since the record.
    pub translation: TranslationChange,
}

/// What the monitor concludes.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Verdict {
    /// Every sensor, in filter order.
    pub sensors: Vec<SensorVerdict>,
}

/// What the verdict's words name besides the report: sensor descriptions and where the
/// re-estimated calibration was written.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VerdictWords {
    /// A description per sensor in filter order (e.g. its bag topic), shown after its name.
    pub labels: Vec<Option<String>>,
    /// The file the re-estimated calibration was written to (`--write-calibration`).
    pub calibration_out: Option<String>,
}

fn unit_sigma(covariance: &Matrix3<f64>, direction: &Vector3<f64>) -> f64 {
    let n = direction.norm();
    if n > 0.0 {
        let u = direction / n;
        (u.transpose() * covariance * u)[(0, 0)].max(0.0).sqrt()
    } else {
        (covariance.trace() / 3.0).max(0.0).sqrt()
    }
}

fn block(s: &SensorReport, at: usize) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| s.final_covariance[at + i][at + j])
}

fn rotation_change(s: &SensorReport) -> RotationChange {
    let v = (s.record.transform.rotation.inverse() * s.estimate.transform.rotation).scaled_axis();
    let record = Matrix3::from_diagonal(&s.record.sigma_rot_deg.map(|d| d.to_radians().powi(2)));
    let sigma = unit_sigma(&(block(s, 0) + record), &v);
    let angle = v.norm();
    let axis = if angle > 0.0 { v / angle } else { v };
    RotationChange {
        vector_deg: v.map(f64::to_degrees).into(),
        angle_deg: angle.to_degrees(),
        sigma_deg: sigma.to_degrees(),
        axis: axis.into(),
        main_axis: axis.iamax(),
    }
}

fn translation_change(s: &SensorReport) -> TranslationChange {
    let v = s.estimate.transform.translation.vector - s.record.transform.translation.vector;
    let record = Matrix3::from_diagonal(&s.record.sigma_trans_m.map(|m| m * m));
    TranslationChange {
        vector_mm: (v * 1e3).into(),
        length_mm: v.norm() * 1e3,
        sigma_mm: unit_sigma(&(block(s, 3) + record), &v) * 1e3,
    }
}

/// The start of the knock candidate an alarm at update `at` confirmed: the first of the
/// updates before it that carried a pending candidate without a break.
fn candidate_start(s: &SensorReport, at: usize) -> Option<f64> {
    s.nis[..at]
        .iter()
        .rev()
        .take_while(|p| p.jump.is_some())
        .last()
        .map(|p| p.t_s)
}

impl SensorVerdict {
    fn of(r: &MonitorReport, s: &SensorReport) -> Self {
        let flagged = r.alarms.iter().find(|a| a.sensor == s.name).map(|a| a.t_s);
        let since = flagged.map(|t| {
            s.nis
                .iter()
                .position(|p| p.t_s >= t)
                .and_then(|at| candidate_start(s, at))
                .unwrap_or(t)
        });
        Self {
            sensor: s.name,
            moved: flagged.is_some(),
            flagged_at_s: flagged,
            since_s: since,
            rotation: rotation_change(s),
            translation: translation_change(s),
        }
    }

    /// `pose1` or `pose1 (label)`.
    fn name(&self, labels: &[Option<String>], k: usize) -> String {
        match labels.get(k).and_then(Option::as_ref) {
            Some(l) => format!("{} ({l})", self.sensor),
            None => self.sensor.to_string(),
        }
    }

    fn moved_words(&self, name: &str, words: &VerdictWords) -> String {
        let r = &self.rotation;
        let a = r.axis;
        let mut text = format!(
            "MOVED: re-mount or check the bracket of {name}: rotated {:.2} deg +- {:.2} about \
             its {} axis (axis [{:.2}, {:.2}, {:.2}] in its own frame)",
            r.angle_deg, r.sigma_deg, AXIS_NAMES[r.main_axis], a[0], a[1], a[2]
        );
        if let (Some(since), Some(flagged)) = (self.since_s, self.flagged_at_s) {
            text.push_str(&format!(" at t={since:.2} s (flagged at {flagged:.2} s)"));
        }
        let t = &self.translation;
        let v = t.vector_mm;
        text.push_str(&format!(
            "; lever arm changed {:.1} mm +- {:.1} ([{:.1}, {:.1}, {:.1}] mm, IMU frame, {})",
            t.length_mm,
            t.sigma_mm,
            v[0],
            v[1],
            v[2],
            if t.is_significant() {
                "significant"
            } else {
                "within its uncertainty"
            }
        ));
        text.push_str(&format!(
            ". Then re-run the calibration of {} (e.g. `msreg calibrate pose-imu` on a drive \
             with {} as pose0), or use the re-estimated calibration {}",
            self.sensor,
            self.sensor,
            match &words.calibration_out {
                Some(path) => format!("written to {path}"),
                None => "(`msreg monitor ... --write-calibration out.yaml`)".into(),
            }
        ));
        text
    }
}

impl Verdict {
    /// The verdict of a monitor run.
    pub fn of(report: &MonitorReport) -> Self {
        Self {
            sensors: report
                .sensors
                .iter()
                .map(|s| SensorVerdict::of(report, s))
                .collect(),
        }
    }

    /// True when a sensor's calibration changed (an alarm was raised).
    pub fn changed(&self) -> bool {
        self.sensors.iter().any(|s| s.moved)
    }

    /// The largest rotation (deg) and translation (mm) of any sensor from the record.
    pub fn largest_change(&self) -> (f64, f64) {
        self.sensors.iter().fold((0.0, 0.0), |(r, t), s| {
            (
                f64::max(r, s.rotation.angle_deg),
                f64::max(t, s.translation.length_mm),
            )
        })
    }

    /// The verdict in plain words, one line per moved sensor, or one line for a healthy rig.
    pub fn lines(&self, words: &VerdictWords) -> Vec<String> {
        if !self.changed() {
            let (rot, trans) = self.largest_change();
            let each: Vec<String> = self
                .sensors
                .iter()
                .enumerate()
                .map(|(k, s)| {
                    format!(
                        "{}: {:.2} deg +- {:.2}, {:.1} mm +- {:.1}",
                        s.name(&words.labels, k),
                        s.rotation.angle_deg,
                        s.rotation.sigma_deg,
                        s.translation.length_mm,
                        s.translation.sigma_mm
                    )
                })
                .collect();
            let count = match self.sensors.len() {
                1 => "the one sensor".to_string(),
                n => format!("all {n} sensors"),
            };
            return vec![format!(
                "OK: {count} within {rot:.2} deg / {trans:.1} mm of the calibration of record \
                 ({}); no action needed",
                each.join("; ")
            )];
        }
        self.sensors
            .iter()
            .enumerate()
            .filter(|(_, s)| s.moved)
            .map(|(k, s)| s.moved_words(&s.name(&words.labels, k), words))
            .collect()
    }
}
