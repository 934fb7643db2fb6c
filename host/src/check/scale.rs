//! The target's scale: the camera's acceleration from its PnP positions against the
//! accelerometer's.
//!
//! PnP on a target whose square size is wrong by a factor `s` returns every camera position
//! scaled by `s` (the images are the same for a board `s` times larger, `s` times further
//! away), so the reprojection error cannot see it; the accelerometer can. For each image `k`
//! the second difference of the PnP positions `h` images apart is the camera's acceleration
//! averaged with a triangle of half-width `H` (about 0.2 s: the noise of the difference falls
//! with `H^2`). The same triangle average of the IMU's side, with the IMU's orientation in
//! the target `R_T_I = R_T_C R_C_I` propagated by the gyro around each image, gives the
//! linear model
//!
//! `a_pnp(k) = s (avg(R_T_I f) - avg(R_T_I) b_a + g_T + avg(R_T_I ([alpha]x + [w]x^2)) r)`
//!
//! linear in the scale `s` and `s g_T` (gravity; the target is static), `s b_a` (the
//! accelerometer bias) and `s r` (the lever arm, the camera in the IMU). It is solved by least
//! squares with the PnP side (the noisy one) as the observation, so its noise does not bias
//! `s`; a sound fit finds |g_T| = 9.81.

use nalgebra::{DMatrix, DVector, Matrix3, UnitQuaternion, Vector3};

use super::motion::{increments, rotation_sensor_imu, Gyro, StampedPose};
use super::sensors::SensorData;
use super::Finding;
use crate::camera_yaml::Target;

/// Half-width of the averaging triangle, s.
pub const HALF_WIDTH_S: f64 = 0.2;
/// Fewest images in the fit.
const MIN_FRAMES: usize = 30;
/// Largest standard error of `s` for an answer: a quarter of the error bound
/// ([`super::findings::MAX_SCALE_ERROR`]), so an error beyond it is a 4-sigma finding.
pub const MAX_SIGMA: f64 = 0.25 * super::findings::MAX_SCALE_ERROR;
/// The fit's gravity must be within this of 9.81 m/s^2 for an answer.
pub const MAX_GRAVITY_ERROR: f64 = 0.5;
/// Standard gravity, m/s^2.
const GRAVITY: f64 = 9.81;

/// The scale check of the camera's PnP poses against the IMU; `offset_s` is cam0's time
/// offset (0 when unknown).
pub fn check(
    data: &SensorData,
    gyro: &Gyro,
    poses: &[StampedPose],
    offset_s: f64,
) -> Option<Finding> {
    let target = data.camera.as_ref()?.target?;
    let (size_m, key) = match target {
        Target::Checkerboard(t) => (t.row_spacing_m, "rowSpacingMeters"),
        Target::AprilGrid(t) => (t.tag_size_m, "tagSize"),
        Target::Board(_) => return None,
    };
    let unclear = |reason: String| Some(Finding::ScaleUnclear { reason });
    let incs = increments(gyro, poses);
    let Some(r_c_i) = rotation_sensor_imu(gyro, &incs, offset_s) else {
        return unclear("the camera-IMU rotation could not be found".into());
    };
    let rows = rows(gyro, poses, offset_s, &r_c_i);
    if rows.len() < MIN_FRAMES {
        return unclear(format!(
            "{} images with neighbours {HALF_WIDTH_S} s either side, at least {MIN_FRAMES} \
             are needed",
            rows.len()
        ));
    }
    let Some(fit) = solve(&rows) else {
        return unclear("the least-squares fit is singular".into());
    };
    if fit.sigma > MAX_SIGMA || (fit.gravity - GRAVITY).abs() > MAX_GRAVITY_ERROR {
        return unclear(format!(
            "the fit is not sound (ratio {:.3}, sigma {:.4}, gravity {:.2} m/s^2): too \
             little acceleration, or the camera and the IMU disagree in rotation",
            fit.scale, fit.sigma, fit.gravity
        ));
    }
    Some(Finding::Scale {
        ratio: fit.scale,
        sigma: fit.sigma,
        size_m,
        key,
        from_corners_csv: data.camera.as_ref().is_some_and(|c| c.from_corners_csv),
        gravity: fit.gravity,
        frames: rows.len(),
    })
}

/// One image's equation: `a_pnp = s y + (s g) - C (s b) + B (s r)`.
struct Row {
    a_pnp: Vector3<f64>,
    c: Matrix3<f64>,
    b: Matrix3<f64>,
    y: Vector3<f64>,
}

fn rows(
    gyro: &Gyro,
    poses: &[StampedPose],
    offset_s: f64,
    r_c_i: &UnitQuaternion<f64>,
) -> Vec<Row> {
    let mut dts: Vec<f64> = poses
        .windows(2)
        .map(|w| (w[1].stamp_ns - w[0].stamp_ns) as f64 * 1e-9)
        .collect();
    dts.sort_by(f64::total_cmp);
    let Some(&dt) = dts.get(dts.len() / 2) else {
        return Vec::new();
    };
    let h = ((HALF_WIDTH_S / dt).round() as usize).max(1);
    (h..poses.len().saturating_sub(h))
        .filter_map(|k| {
            let (before, at, after) = (&poses[k - h], &poses[k], &poses[k + h]);
            let d_minus = (at.stamp_ns - before.stamp_ns) as f64 * 1e-9;
            let d_plus = (after.stamp_ns - at.stamp_ns) as f64 * 1e-9;
            let nominal = h as f64 * dt;
            if (d_minus - nominal).abs() > 0.5 * dt || (d_plus - nominal).abs() > 0.5 * dt {
                return None;
            }
            let p = |s: &StampedPose| s.pose.translation.vector;
            let half = 0.5 * (d_plus + d_minus);
            let a_pnp = ((p(after) - p(at)) / d_plus - (p(at) - p(before)) / d_minus) / half;
            let centre = gyro.time_of(at.stamp_ns) + offset_s;
            let r_t_i = at.pose.rotation * r_c_i;
            imu_side(gyro, centre, half, &r_t_i).map(|(y, c, b)| Row { a_pnp, c, b, y })
        })
        .collect()
}

/// The triangle averages around `centre` (IMU seconds) with half-width `half`:
/// `avg(R f)`, `avg(R)`, `avg(R K)`; `None` when the window leaves the IMU's span.
fn imu_side(
    gyro: &Gyro,
    centre: f64,
    half: f64,
    r_centre: &UnitQuaternion<f64>,
) -> Option<(Vector3<f64>, Matrix3<f64>, Matrix3<f64>)> {
    let t = &gyro.t;
    if centre - half < t[1] || centre + half > t[t.len() - 2] {
        return None;
    }
    let j0 = t.partition_point(|&x| x <= centre);
    let mut samples: Vec<(usize, UnitQuaternion<f64>)> = Vec::new();
    let (mut r, mut t_prev) = (*r_centre, centre);
    for (j, &tj) in t.iter().enumerate().take(t.len() - 1).skip(j0) {
        if tj > centre + half {
            break;
        }
        r *= UnitQuaternion::from_scaled_axis(gyro.imu[j - 1].gyro * (tj - t_prev));
        t_prev = tj;
        samples.push((j, r));
    }
    let (mut r, mut t_prev) = (*r_centre, centre);
    for j in (1..j0).rev() {
        if t[j] < centre - half {
            break;
        }
        r *= UnitQuaternion::from_scaled_axis(-gyro.imu[j].gyro * (t_prev - t[j]));
        t_prev = t[j];
        samples.push((j, r));
    }
    let (mut y, mut c, mut b, mut total) =
        (Vector3::zeros(), Matrix3::zeros(), Matrix3::zeros(), 0.0);
    for (j, r) in samples {
        let w = half - (t[j] - centre).abs();
        let rm = r.to_rotation_matrix().into_inner();
        let omega = gyro.imu[j].gyro;
        let alpha = (gyro.imu[j + 1].gyro - gyro.imu[j - 1].gyro) / (t[j + 1] - t[j - 1]);
        let k = alpha.cross_matrix() + omega.cross_matrix() * omega.cross_matrix();
        y += rm * gyro.imu[j].accel * w;
        c += rm * w;
        b += rm * k * w;
        total += w;
    }
    (total > 0.0).then(|| (y / total, c / total, b / total))
}

/// The least-squares fit.
struct Fit {
    scale: f64,
    sigma: f64,
    gravity: f64,
}

/// Solves `[y, I, -C, B] [s, s g, s b, s r] = a_pnp` over all rows.
fn solve(rows: &[Row]) -> Option<Fit> {
    let n = rows.len();
    let mut a = DMatrix::zeros(3 * n, 10);
    let mut obs = DVector::zeros(3 * n);
    for (i, row) in rows.iter().enumerate() {
        let r = 3 * i;
        a.view_mut((r, 0), (3, 1)).copy_from(&row.y);
        a.view_mut((r, 1), (3, 3)).copy_from(&Matrix3::identity());
        a.view_mut((r, 4), (3, 3)).copy_from(&(-row.c));
        a.view_mut((r, 7), (3, 3)).copy_from(&row.b);
        obs.rows_mut(r, 3).copy_from(&row.a_pnp);
    }
    let inverse = (a.transpose() * &a).try_inverse()?;
    let x = &inverse * (a.transpose() * &obs);
    let residual = &a * &x - &obs;
    let dof = (3 * n).saturating_sub(10).max(1) as f64;
    let variance = residual.norm_squared() / dof;
    let scale = x[0];
    (scale > 0.0).then(|| Fit {
        scale,
        sigma: (inverse[(0, 0)] * variance).sqrt(),
        gravity: Vector3::new(x[1], x[2], x[3]).norm() / scale,
    })
}
