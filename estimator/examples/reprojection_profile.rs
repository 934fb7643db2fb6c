//! Profiling harness (callgrind): 42-corner reprojection updates of `CameraImuEkf<f32>`, the
//! firmware bench's scene. `valgrind --tool=callgrind target/release/examples/reprojection_profile`.
use msreg_estimator::camera::{radtan::RadTan, Camera, Distortion, Intrinsics, Projection};
use msreg_estimator::na::{UnitQuaternion, Vector2, Vector3};
use msreg_estimator::{
    CameraImuEkf, CornerObservation, CornerSet, FilterConfig, ImuNoise, ImuSample, InitialState,
    Pose, SOLE_SENSOR, TARGET_FRAME,
};

const BOARD: (usize, usize) = (6, 7);

fn run() -> Option<()> {
    let noise = ImuNoise {
        gyro_noise_density: 1.7e-4,
        accel_noise_density: 2.0e-3,
        gyro_random_walk: 1.9e-5,
        accel_random_walk: 3.0e-3,
    };
    let gravity = Vector3::new(0.0, 0.0, 9.81);
    let init = InitialState::<f32, 1>::at_rest(gravity)?
        .with_extrinsic(SOLE_SENSOR, Pose::identity(), 0.01, 0.01)
        .with_time_offset(SOLE_SENSOR, 0.0, 0.005);
    let mut ekf = CameraImuEkf::<f32>::new(&FilterConfig::new(noise), &init).ok()?;
    let stamp_ns = 1_000_000_000;
    ekf.propagate(&ImuSample {
        stamp_ns,
        gyro: Vector3::zeros(),
        accel: gravity,
    })
    .ok()?;
    let camera = Camera::new(
        Projection::Pinhole,
        Intrinsics {
            fu: 458.7,
            fv: 457.3,
            cu: 367.2,
            cv: 248.4,
        },
        Distortion::RadTan(RadTan {
            k1: -0.283,
            k2: 0.074,
            p1: 2.0e-4,
            p2: 1.8e-5,
            k3: 0.0,
        }),
        (752, 480),
    )
    .ok()?;
    let t_c_t = Pose::new(UnitQuaternion::identity(), Vector3::new(-0.1, -0.12, 0.8));
    let t_g_c = ekf.imu().pose().compose(&ekf.extrinsic(SOLE_SENSOR));
    ekf.init_frame(TARGET_FRAME, t_g_c.compose(&t_c_t), 0.05, 0.05)
        .ok()?;
    let mut corners = [CornerObservation {
        point_in_target: Vector3::zeros(),
        pixel: Vector2::zeros(),
    }; BOARD.0 * BOARD.1];
    for (k, corner) in corners.iter_mut().enumerate() {
        let (r, c) = (k / BOARD.1, k % BOARD.1);
        corner.point_in_target = Vector3::new(r as f32 * 0.04, c as f32 * 0.04, 0.0);
        corner.pixel = camera
            .project(&t_c_t.transform_point(&corner.point_in_target))?
            .pixel;
    }
    let meas = CornerSet {
        stamp_ns,
        corners: &corners,
        pixel_sigma: 0.1,
    };
    for _ in 0..100 {
        let r = ekf
            .update_reprojection(SOLE_SENSOR, TARGET_FRAME, &camera, &meas)
            .ok()?;
        if !r.accepted {
            return None;
        }
    }
    Some(())
}

fn main() {
    assert!(run().is_some());
}
