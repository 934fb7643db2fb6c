//! Consistency check of the embedded sequence, independent of the estimator: strapdown
//! integration of the noise-free IMU readings must land on the analytic trajectory. If it
//! does not, the trajectory's derivatives (body rates, specific force) are wrong and no
//! filter result on this data would mean anything.

use nalgebra::{UnitQuaternion, Vector3};

use crate::scenario::{Event, Scenario, ScenarioConfig};
use crate::trajectory::GRAVITY;

/// How far dead reckoning drifted from the analytic end pose.
#[derive(Clone, Copy, Debug)]
pub struct DeadReckoning {
    /// IMU samples integrated.
    pub samples: u32,
    /// Rotation error at the end, rad.
    pub rotation_error: f32,
    /// Position error at the end, m.
    pub position_error: f32,
}

impl DeadReckoning {
    /// Whether the drift is within what second-order integration at 400 Hz allows.
    pub fn passed(&self) -> bool {
        self.rotation_error < 1e-3 && self.position_error < 1e-2
    }
}

/// Integrates the noise-free IMU of `config` from the true initial state (trapezoidal
/// rates and accelerations) and compares the end with the analytic pose.
pub fn dead_reckon(config: &ScenarioConfig) -> DeadReckoning {
    let exact = ScenarioConfig {
        noise_scale: 0.0,
        ..*config
    };
    let scenario = Scenario::new(exact);
    let trajectory = *scenario.trajectory();
    let g = Vector3::new(0.0, 0.0, -GRAVITY);
    let dt = config.imu_period_ns as f32 * 1e-9;

    let mut r_g_i = UnitQuaternion::identity();
    let (mut p, mut v) = (Vector3::zeros(), Vector3::zeros());
    let mut prev: Option<(Vector3<f32>, Vector3<f32>)> = None;
    let mut samples = 0;
    for event in scenario {
        let Event::Imu(imu) = event else { continue };
        samples += 1;
        if let Some((gyro0, accel0)) = prev {
            let a0 = r_g_i * accel0 + g;
            r_g_i *= UnitQuaternion::from_scaled_axis((gyro0 + imu.gyro) * (0.5 * dt));
            let a1 = r_g_i * imu.accel + g;
            p += v * dt + (a0 * 2.0 + a1) * (dt * dt / 6.0);
            v += (a0 + a1) * (0.5 * dt);
        }
        prev = Some((imu.gyro, imu.accel));
    }

    let end = trajectory.kinematics(config.duration_ns as f32 * 1e-9);
    DeadReckoning {
        samples,
        rotation_error: r_g_i.angle_to(&end.t_g_i.rotation),
        position_error: (p - end.t_g_i.translation.vector).norm(),
    }
}
