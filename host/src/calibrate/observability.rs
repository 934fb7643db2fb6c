//! What a calibration observed, per degree of freedom, in words: how far each sigma shrank
//! from its prior, and which directions the motion could not observe (held at their prior
//! by the filter, see `Ekf::hold_translation_axis`).

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// A DoF whose sigma shrank below this share of its prior counts as observed.
const OBSERVED_BELOW: f64 = 0.5;
/// A DoF whose sigma stays above this share of its prior learned (next to) nothing.
const UNOBSERVED_ABOVE: f64 = 0.8;

/// One row of the observability table.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct DofObservability {
    /// `rotation x`, ..., `translation z`, `time offset`, or a held direction.
    pub dof: String,
    /// Final 1-sigma (deg for rotations, m for translations, ms for the time offset).
    pub sigma: f64,
    /// Prior 1-sigma in the same unit.
    pub prior_sigma: f64,
    /// `observed`, `weak`, `not observable`, or `not trusted` (an input contradicts
    /// another, e.g. the pose sensor's rotation the gyro's).
    pub status: &'static str,
    /// Why, when not observed.
    pub reason: String,
}

/// A translation direction the filter held at its prior, with the motion's reason.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldDirection {
    /// Unit direction (IMU frame).
    pub axis: Vector3<f64>,
    /// Why it is not observable.
    pub reason: String,
}

/// The table for an extrinsic and time offset: `sigma` and `prior` in the order rotation
/// x, y, z (rad), translation x, y, z (m), time offset (s); `translation_cov` the final 3x3
/// translation covariance (for the held direction's own row).
pub fn table(
    sigma: &[f64; 7],
    prior: &[f64; 7],
    translation_cov: &Matrix3<f64>,
    held: Option<&HeldDirection>,
) -> Vec<DofObservability> {
    const NAMES: [&str; 7] = [
        "rotation x",
        "rotation y",
        "rotation z",
        "translation x",
        "translation y",
        "translation z",
        "time offset",
    ];
    let unit = |k: usize| match k {
        0..=2 => 180.0 / std::f64::consts::PI,
        6 => 1e3,
        _ => 1.0,
    };
    let mut rows: Vec<DofObservability> = (0..7)
        .filter(|&k| prior[k] > 0.0)
        .map(|k| row(NAMES[k], sigma[k] * unit(k), prior[k] * unit(k), held))
        .collect();
    if let Some(h) = held {
        let along = (h.axis.transpose() * translation_cov * h.axis)[0]
            .max(0.0)
            .sqrt();
        let a = h.axis;
        rows.push(DofObservability {
            dof: format!("translation along [{:.3}, {:.3}, {:.3}]", a.x, a.y, a.z),
            sigma: along,
            prior_sigma: prior[3],
            status: "not observable",
            reason: format!("{}; held at its prior", h.reason),
        });
    }
    rows
}

fn row(name: &str, sigma: f64, prior: f64, held: Option<&HeldDirection>) -> DofObservability {
    let ratio = sigma / prior;
    let (status, reason) = if ratio < OBSERVED_BELOW {
        ("observed", String::new())
    } else if ratio > UNOBSERVED_ABOVE {
        let why = match held {
            Some(h) if name.starts_with("translation") => h.reason.clone(),
            _ => "the motion did not excite it".to_string(),
        };
        ("not observable", why)
    } else {
        (
            "weak",
            format!("sigma is {:.0} % of its prior", 100.0 * ratio),
        )
    };
    DofObservability {
        dof: name.to_string(),
        sigma,
        prior_sigma: prior,
        status,
        reason,
    }
}

/// The largest 1-sigma of a translation covariance in the plane perpendicular to `axis`
/// (all of it without one), and its direction: what a convergence check may demand when
/// `axis` is held.
pub fn largest_sigma_across(
    cov: &Matrix3<f64>,
    axis: Option<&Vector3<f64>>,
) -> (f64, Vector3<f64>) {
    let projected = match axis {
        Some(a) => {
            let p = Matrix3::identity() - a * a.transpose();
            p * cov * p
        }
        None => *cov,
    };
    let eig = projected.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    (
        eig.eigenvalues[k].max(0.0).sqrt(),
        eig.eigenvectors.column(k).into_owned(),
    )
}

/// The names of the axes (`x`, `y`, `z`) whose value exceeds `limit`, joined by commas.
pub fn axes_above(values: &Vector3<f64>, limit: f64) -> String {
    ["x", "y", "z"]
        .iter()
        .zip(values.iter())
        .filter(|(_, v)| **v > limit)
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_direction_is_excluded_from_the_across_sigma() {
        let cov = Matrix3::from_diagonal(&Vector3::new(1e-4, 4e-4, 0.25));
        let (sigma, direction) = largest_sigma_across(&cov, None);
        assert!((sigma - 0.5).abs() < 1e-12 && direction.z.abs() > 1.0 - 1e-12);
        let z = Vector3::z();
        let (sigma, direction) = largest_sigma_across(&cov, Some(&z));
        assert!((sigma - 0.02).abs() < 1e-12 && direction.y.abs() > 1.0 - 1e-12);
        assert_eq!(axes_above(&Vector3::new(0.6, 0.1, 0.7), 0.5), "x, z");
    }

    #[test]
    fn rows_say_what_was_observed() {
        let prior = [0.03, 0.03, 0.03, 0.5, 0.5, 0.5, 0.05];
        let sigma = [0.001, 0.001, 0.02, 0.01, 0.01, 0.49, 1e-4];
        let cov = Matrix3::from_diagonal(&Vector3::new(1e-4, 1e-4, 0.49 * 0.49));
        let held = HeldDirection {
            axis: Vector3::z(),
            reason: "planar motion".into(),
        };
        let rows = table(&sigma, &prior, &cov, Some(&held));
        let status: Vec<&str> = rows.iter().map(|r| r.status).collect();
        assert_eq!(
            status,
            [
                "observed",
                "observed",
                "weak",
                "observed",
                "observed",
                "not observable",
                "observed",
                "not observable"
            ]
        );
        assert_eq!(rows[5].reason, "planar motion");
        assert!((rows[7].sigma - 0.49).abs() < 1e-12);
        assert!((rows[6].sigma - 0.1).abs() < 1e-12, "time offset in ms");
    }
}
