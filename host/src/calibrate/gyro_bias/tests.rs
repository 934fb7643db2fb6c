use super::*;

/// Body rate of a tumbling rotation (rad/s), smooth, about all three axes.
fn rate(t: f64) -> Vector3<f64> {
    Vector3::new(
        1.2 * (1.3 * t).sin(),
        0.9 * (0.7 * t + 1.0).sin(),
        1.5 * (0.45 * t + 2.0).cos(),
    )
}

/// The true IMU attitude at 1 kHz steps (RK-free: 100 sub-steps of the midpoint rate per
/// millisecond), instantaneous gyro samples at `rate_hz` carrying `bias` and a small
/// deterministic ripple, and the sensor's rotation increments at 20 Hz seen at `r_i_s`.
fn recording(
    bias: &Vector3<f64>,
    r_i_s: &UnitQuaternion<f64>,
    rate_hz: f64,
) -> (Vec<ImuRecord>, Vec<RotationIncrement>) {
    let duration = 20.0;
    let fine = 1e-5;
    let attitude_at = {
        let mut table = vec![UnitQuaternion::identity()];
        let mut q = UnitQuaternion::identity();
        let steps = (duration / fine) as usize;
        for i in 0..steps {
            let t = i as f64 * fine;
            q *= lie::exp(&(rate(t + 0.5 * fine) * fine));
            if (i + 1) % 100 == 0 {
                table.push(q);
            }
        }
        move |t: f64| table[(t * 1e3).round() as usize]
    };
    let period = 1.0 / rate_hz;
    let imu: Vec<ImuRecord> = (0..=(duration / period) as usize)
        .map(|k| {
            let t = k as f64 * period;
            ImuRecord {
                stamp_ns: (t * 1e9).round() as u64,
                gyro: rate(t) + bias + Vector3::repeat(1e-4 * (37.0 * t).sin()),
                accel: Vector3::new(0.0, 0.0, 9.81),
            }
        })
        .collect();
    let increments = (1..390)
        .map(|k| {
            let (ta, tb) = (k as f64 * 0.05, (k + 1) as f64 * 0.05);
            let (ra, rb) = (attitude_at(ta) * r_i_s, attitude_at(tb) * r_i_s);
            ((ta * 1e9) as u64, (tb * 1e9) as u64, ra.inverse() * rb)
        })
        .collect();
    (imu, increments)
}

fn mounting() -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(0.3, -1.2, 2.0)
}

#[test]
fn residual_jacobian_matches_central_differences() {
    let bias = Vector3::new(0.02, -0.05, 0.08);
    let (imu, increments) = recording(&bias, &mounting(), 200.0);
    let (from, to, q) = increments[40];
    let increment = Increment {
        pieces: gyro_pieces(&imu, from, to).expect("inside the data"),
        measured: mounting() * q * mounting().inverse(),
    };
    // Far from the truth, so the residual (and Jl^-1 of it) is not small.
    let at = Vector3::new(0.3, -0.2, 0.4);
    let (_, jacobian) = residual(&increment, &at);
    let h = 1e-6;
    for c in 0..3 {
        let mut e = Vector3::zeros();
        e[c] = h;
        let fd =
            (residual(&increment, &(at + e)).0 - residual(&increment, &(at - e)).0) / (2.0 * h);
        let error = (fd - jacobian.column(c)).norm();
        assert!(
            error < 1e-8,
            "column {c}: analytic {} vs FD {fd}",
            jacobian.column(c)
        );
    }
}

#[test]
fn recovers_a_large_bias_and_the_mounting_without_a_standstill() {
    // The size of the EuRoC ADIS16448's turn-on bias, on every axis.
    let bias = Vector3::new(0.03, -0.05, 0.08);
    for rate_hz in [200.0, 400.0] {
        let (imu, increments) = recording(&bias, &mounting(), rate_hz);
        let (rotation, estimate) = hand_eye_with_gyro_bias(&imu, &increments, 10);
        let estimate = estimate.expect("a bias fit");
        let rotation = rotation.expect("a hand-eye rotation").rotation;
        let bias_error = (estimate.bias - bias).amax();
        let rotation_error = rotation.angle_to(&mounting()).to_degrees();
        // Exact increments: what remains is the gyro ripple (1e-4 rad/s) and the
        // trapezoid of the instantaneous samples.
        assert!(
            bias_error < 2e-4,
            "{rate_hz} Hz: bias error {bias_error} rad/s"
        );
        assert!(
            rotation_error < 0.01,
            "{rate_hz} Hz: rotation error {rotation_error} deg"
        );
        assert!(estimate.sigma.amax() < 1e-3, "{:?}", estimate.sigma);
        assert_eq!(estimate.pairs, increments.len());
    }
}

#[test]
fn zero_bias_hand_eye_is_skewed_by_the_bias_that_the_alternation_removes() {
    let bias = Vector3::new(0.03, -0.05, 0.08);
    let (imu, increments) = recording(&bias, &mounting(), 200.0);
    let naive = init::hand_eye_from_pairs(
        init::rotation_pairs(&imu, increments.iter().copied(), &Vector3::zeros()),
        10,
    )
    .expect("hand-eye");
    let (joint, _) = hand_eye_with_gyro_bias(&imu, &increments, 10);
    let naive_error = naive.rotation.angle_to(&mounting()).to_degrees();
    let joint_error = joint
        .expect("hand-eye")
        .rotation
        .angle_to(&mounting())
        .to_degrees();
    assert!(
        naive_error > 10.0 * joint_error,
        "{naive_error} vs {joint_error}"
    );
}

#[test]
fn too_few_increments_give_no_estimate() {
    let (imu, increments) = recording(&Vector3::zeros(), &mounting(), 200.0);
    assert!(estimate_gyro_bias(&imu, &increments[..5], &mounting(), &Vector3::zeros()).is_none());
}
