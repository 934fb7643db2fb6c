use super::*;

/// Rotation-vector pairs of a drive: yaw increments about the sensor's `axis_sensor`, with
/// `wobble` of rotation about the two axes across it, seen in the IMU through `r_i_s`.
fn pairs(
    r_i_s: &UnitQuaternion<f64>,
    axis_sensor: &Vector3<f64>,
    wobble: f64,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let across = orthogonal_unit(axis_sensor);
    let across2 = axis_sensor.cross(&across);
    (0..400)
        .map(|k| {
            let t = k as f64 * 0.1;
            let yaw = 0.05 * (0.3 * t).sin();
            let r_s = axis_sensor * yaw
                + across * wobble * (1.7 * t).cos()
                + across2 * wobble * (2.3 * t + 1.0).sin();
            (r_i_s * r_s, r_s)
        })
        .collect()
}

#[test]
fn planar_drive_gives_the_axis_in_both_frames_and_their_alignment() {
    let r_i_s = UnitQuaternion::from_euler_angles(0.4, -1.1, 2.5);
    let axis_sensor = Vector3::new(0.2, -0.3, 0.93).normalize();
    let p = detect(&pairs(&r_i_s, &axis_sensor, 0.005)).expect("planar");
    assert!(p.axis_ratio < PLANAR_AXIS_RATIO);
    // The wobble is not exactly uncorrelated with the yaw over the record: ~1e-3 of tilt.
    assert!(
        (p.axis_sensor - axis_sensor).norm() < 5e-3,
        "{}",
        p.axis_sensor
    );
    assert!((p.axis_imu - r_i_s * axis_sensor).norm() < 5e-3);
    // Both axes are the same direction seen through the rigid mounting.
    assert!((p.axis_imu - r_i_s * p.axis_sensor).norm() < 1e-9);
    assert!((p.alignment * p.axis_sensor - p.axis_imu).norm() < 1e-12);
    // The alignment is the truth up to a rotation about the IMU axis.
    let rest = r_i_s * p.alignment.inverse();
    let angle = rest.scaled_axis();
    assert!(angle.cross(&p.axis_imu).norm() < 1e-6, "{angle}");
}

#[test]
fn two_axis_motion_is_not_planar() {
    let r_i_s = UnitQuaternion::from_euler_angles(0.4, -1.1, 2.5);
    assert!(detect(&pairs(&r_i_s, &Vector3::z(), 0.03)).is_none());
}

#[test]
fn too_few_pairs_are_not_called_planar() {
    let r_i_s = UnitQuaternion::identity();
    let few: Vec<_> = pairs(&r_i_s, &Vector3::z(), 0.0)
        .into_iter()
        .take(MIN_PAIRS - 1)
        .collect();
    assert!(detect(&few).is_none());
}

#[test]
fn golden_section_finds_a_parabola_minimum() {
    let x = golden_section(|a| (a - 0.123).powi(2) + 2.0, -1.0, 1.0);
    assert!((x - 0.123).abs() < 1e-5, "{x}");
}
