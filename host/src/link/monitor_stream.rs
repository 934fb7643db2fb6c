//! A drive (`imu0/`, `pose0/`, `pose1/`, `calibration.yaml`) as the message sequence of the
//! device's monitoring layout (`SensorSet::Monitor`): the [`Config`] carries the prior of
//! `msreg monitor`'s monitor run exactly as `monitor::monitor_prior` computed it (IMU state
//! and sigmas, both sensors' calibration of record, the planar hold, the health tuning), and
//! both sensors' odometry follows `monitor::pose_steps`, the rule the host replay applies.
//! Nothing of the prior or the sequencing is derived a second time here.

use super::stream::{f32x3, ReplayStream, StreamOptions};
use super::LinkError;
use crate::monitor::{
    monitor_prior, pose_steps, FilterPrior, MonitorInput, MonitorOptions, PoseStep,
    ZERO_VELOCITY_EVERY,
};
use msreg_estimator::chi2::Confidence;
use msreg_estimator::filter::MonitorEkf;
use msreg_estimator::state::SensorPrior as FilterSensorPrior;
use msreg_estimator::{FilterConfig, HealthConfig, InitialState, Pose as FilterPose, SensorId};
use msreg_protocol::{
    Anchor, Config, Gate, HostMsg, ImuNoise, ImuPrior, ImuStart, MonitorSetup, Pose, RelativePose,
    SensorPrior, SensorSet,
};

/// The wire gate of a confidence.
fn gate(c: Confidence) -> Gate {
    match c {
        Confidence::P90 => Gate::P90,
        Confidence::P95 => Gate::P95,
        Confidence::P99 => Gate::P99,
        Confidence::P995 => Gate::P995,
        Confidence::P999 => Gate::P999,
        Confidence::P9999 => Gate::P9999,
        Confidence::P99999 => Gate::P99999,
    }
}

fn wire_pose(p: &FilterPose<f64>) -> Pose {
    let q = p.rotation.quaternion();
    Pose {
        rotation_wxyz: [q.w, q.i, q.j, q.k].map(|x| x as f32),
        translation_m: f32x3(&p.translation),
    }
}

fn sensor_prior(p: &FilterSensorPrior<f64>) -> SensorPrior {
    SensorPrior {
        extrinsic: wire_pose(&p.state.extrinsic),
        sigma_rotation_rad: p.sigma_rotation as f32,
        sigma_translation_m: p.sigma_translation as f32,
        time_offset_s: p.state.time_offset as f32,
        sigma_time_offset_s: p.sigma_time_offset as f32,
    }
}

fn imu_start(init: &InitialState<f64, 2>) -> ImuStart {
    let imu = &init.imu;
    let q = imu.rotation.quaternion();
    ImuStart {
        rotation_wxyz: [q.w, q.i, q.j, q.k].map(|x| x as f32),
        position_m: f32x3(&imu.position),
        velocity_m_s: f32x3(&imu.velocity),
        gyro_bias_rad_s: f32x3(&imu.gyro_bias),
        accel_bias_m_s2: f32x3(&imu.accel_bias),
        sigmas: [
            init.sigma_orientation,
            init.sigma_position,
            init.sigma_velocity,
            init.sigma_gyro_bias,
            init.sigma_accel_bias,
        ]
        .map(|x| x as f32),
    }
}

/// The tuning the wire does not carry: the device starts from `FilterConfig::new` and
/// `HealthConfig::default()` with the jump-anchored detector on (its monitoring session)
/// and sets only the gate, the IMU gap, the step forgetting, the resolvable-step factor and
/// the step confidence. A prior tuned in any other field could not be reproduced.
fn untransmitted_tuning_is_default(c: &FilterConfig<f64>) -> bool {
    let mut expected = FilterConfig::new(c.imu_noise);
    expected.gate = c.gate;
    expected.max_imu_gap_ns = c.max_imu_gap_ns;
    expected.health = HealthConfig {
        step_forgetting: c.health.step_forgetting,
        resolvable_step_factor: c.health.resolvable_step_factor,
        step_confidence: c.health.step_confidence,
        ..HealthConfig::default().with_jump_detector()
    };
    expected == *c
}

/// The device configuration of a monitor prior.
pub fn monitor_config(prior: &FilterPrior, estimate_period_ns: u32) -> Result<Config, LinkError> {
    let c = &prior.config;
    if !untransmitted_tuning_is_default(c) {
        return Err(LinkError::UntransmittedTuning);
    }
    let n = &c.imu_noise;
    Ok(Config {
        sensors: SensorSet::Monitor(MonitorSetup {
            pose1: sensor_prior(&prior.init.sensors[1]),
            hold_translation_axis: prior.hold_axis.map(|a| f32x3(&a)),
            step_forgetting: c.health.step_forgetting as f32,
            resolvable_step_factor: c.health.resolvable_step_factor as f32,
            step_confidence: gate(c.health.step_confidence),
        }),
        imu_noise: ImuNoise {
            gyro_noise_density: n.gyro_noise_density as f32,
            accel_noise_density: n.accel_noise_density as f32,
            gyro_random_walk: n.gyro_random_walk as f32,
            accel_random_walk: n.accel_random_walk as f32,
        },
        gate: gate(c.gate),
        max_imu_gap_ns: u32::try_from(c.max_imu_gap_ns).unwrap_or(u32::MAX),
        imu_prior: ImuPrior::State(imu_start(&prior.init)),
        sensor: sensor_prior(&prior.init.sensors[0]),
        zero_velocity_until_ns: prior.zero_velocity_until_ns.unwrap_or(0),
        zero_velocity_every: ZERO_VELOCITY_EVERY,
        estimate_period_ns,
    })
}

/// The message of one odometry step of sensor `s`.
fn step_message(step: &PoseStep, s: SensorId) -> HostMsg {
    match step {
        PoseStep::Anchor(stamp_ns) => HostMsg::Anchor(Anchor {
            stamp_ns: *stamp_ns,
            sensor: s.wire(),
        }),
        PoseStep::Increment(m) => {
            let sd = |i: usize| m.covariance[(i, i)].sqrt() as f32;
            HostMsg::RelativePose(RelativePose {
                stamp_from_ns: m.stamp_from_ns,
                stamp_to_ns: m.stamp_to_ns,
                delta: wire_pose(&m.delta),
                sigma_rotation_rad: [sd(0), sd(1), sd(2)],
                sigma_translation_m: [sd(3), sd(4), sd(5)],
                sensor: s.wire(),
            })
        }
    }
}

/// The whole replay of a drive to the device's monitoring layout.
pub fn build_monitor_stream(
    input: &MonitorInput,
    monitor: &MonitorOptions,
    options: &StreamOptions,
) -> Result<ReplayStream, LinkError> {
    let (_, prior) = monitor_prior(input, monitor)?;
    let config = monitor_config(&prior, options.estimate_period_ns)?;
    let ekf: MonitorEkf<f64> = prior.filter()?;
    let start_ns = input.imu[0].stamp_ns;
    let mut measurements = Vec::new();
    let mut skipped = 0;
    for s in MonitorEkf::<f64>::sensor_ids() {
        let (steps, _) = pose_steps(&ekf, s, input, start_ns);
        skipped += input.poses[s.index()].len() - steps.len();
        measurements.extend(steps.iter().map(|p| (p.stamp_ns(), step_message(p, s))));
    }
    // Stamp order (stable: sensor 0 first at equal stamps); the device holds each in its
    // sensor's queue until due and fuses the due ones in IMU-time order.
    measurements.sort_by_key(|(stamp, _)| *stamp);
    Ok(ReplayStream::interleaved(
        config,
        input.imu,
        &measurements,
        (options.pose_lead_ns, options.batch),
        skipped,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::DriveFiles;
    use crate::sim::{simulate_drive, DriveSimConfig, KnockTarget};

    fn close(a: f32, b: f64) -> bool {
        (f64::from(a) - b).abs() <= 1e-6 * b.abs().max(1e-3)
    }

    #[test]
    fn the_config_carries_the_monitor_prior_and_both_sensors_odometry() {
        let sim = simulate_drive(&DriveSimConfig {
            seed: 7,
            duration_s: 12.0,
            knock_target: KnockTarget::None,
            ..DriveSimConfig::default()
        })
        .expect("simulate");
        let dir = tempfile::tempdir().expect("temp dir");
        sim.write(dir.path()).expect("written");
        let files = DriveFiles::read(dir.path(), None).expect("read");
        let input = files.input().expect("input");
        let options = MonitorOptions::default();
        let (_, prior) = monitor_prior(&input, &options).expect("prior");
        let stream =
            build_monitor_stream(&input, &options, &StreamOptions::default()).expect("stream");
        let c = &stream.config;
        let SensorSet::Monitor(m) = &c.sensors else {
            panic!("not the monitoring layout: {:?}", c.sensors);
        };
        let ImuPrior::State(imu) = &c.imu_prior else {
            panic!("not the host's IMU state: {:?}", c.imu_prior);
        };
        // The IMU state and sigmas as the host's start computed them (f32-rounded).
        let q = prior.init.imu.rotation.quaternion();
        for (a, b) in imu.rotation_wxyz.iter().zip([q.w, q.i, q.j, q.k]) {
            assert!(close(*a, b), "{imu:?}");
        }
        for k in 0..3 {
            assert!(close(imu.velocity_m_s[k], prior.init.imu.velocity[k]));
            assert!(close(imu.gyro_bias_rad_s[k], prior.init.imu.gyro_bias[k]));
            assert!(close(imu.accel_bias_m_s2[k], prior.init.imu.accel_bias[k]));
        }
        assert!(close(imu.sigmas[0], prior.init.sigma_orientation));
        assert!(close(imu.sigmas[2], prior.init.sigma_velocity));
        // Both sensors' calibration of record and sigmas, the hold and the health tuning.
        for (wire, host) in [c.sensor, m.pose1].iter().zip(&prior.init.sensors) {
            assert!(close(wire.sigma_rotation_rad, host.sigma_rotation));
            assert!(close(wire.sigma_translation_m, host.sigma_translation));
            assert!(close(wire.time_offset_s, host.state.time_offset));
            assert!(close(wire.sigma_time_offset_s, host.sigma_time_offset));
            for k in 0..3 {
                assert!(close(
                    wire.extrinsic.translation_m[k],
                    host.state.extrinsic.translation[k]
                ));
            }
        }
        let axis = prior.hold_axis.expect("a drive is planar");
        let held = m.hold_translation_axis.expect("hold sent");
        assert!((0..3).all(|k| close(held[k], axis[k])));
        assert!(close(m.step_forgetting, options.step_forgetting));
        assert!(close(m.resolvable_step_factor, 1.0));
        assert_eq!(m.step_confidence, gate(options.step_confidence));
        assert_eq!(m.step_confidence, Gate::P99999);
        // Each sensor's odometry: one anchor, then increments, in stamp order.
        let ekf = prior.filter().expect("filter");
        for s in MonitorEkf::<f64>::sensor_ids() {
            let (steps, _) = pose_steps(&ekf, s, &input, sim.imu[0].stamp_ns);
            let s = s.wire();
            let sent: Vec<&HostMsg> = stream
                .messages
                .iter()
                .map(|(_, msg)| msg)
                .filter(|msg| match msg {
                    HostMsg::Anchor(a) => a.sensor == s,
                    HostMsg::RelativePose(r) => r.sensor == s,
                    _ => false,
                })
                .collect();
            assert_eq!(sent.len(), steps.len(), "sensor {s}");
            assert!(matches!(sent[0], HostMsg::Anchor(_)), "sensor {s}");
            assert_eq!(
                sent.iter()
                    .filter(|m| matches!(m, HostMsg::Anchor(_)))
                    .count(),
                1,
                "sensor {s}: a drive has no gaps"
            );
        }
    }
}
