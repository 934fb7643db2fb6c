//! Driver samples into the estimator at the firmware's feed seam: the link session turns an
//! IMU sample into `ImuSample<f32>` and calls `propagate` on its filter
//! (`firmware/src/session.rs`, `on_imu`; `firmware/src/filter.rs`, `Filter::propagate`).
//! Here the samples come from FIFO bursts of the mocked part through
//! `msreg_icm42688::estimator::imu_sample`, into the firmware's pose-IMU layout.

mod common;

use common::{default_init_sequence, fifo_read, packet3};
use embedded_hal_mock::eh1::delay::NoopDelay;
use embedded_hal_mock::eh1::spi::Mock;
use msreg_estimator::{FilterConfig, ImuNoise, InitialState, PoseImuEkf};
use msreg_icm42688::estimator::imu_sample;
use msreg_icm42688::{Config, DataReady, Icm42688, Sample};

/// A level IMU turning about its z axis at a constant rate: accel +1 g on z (4096 LSB at
/// +-8 g), gyro z 939 LSB at +-1000 deg/s (0.5 rad/s); 500 samples at 500 Hz, one per burst.
#[test]
fn driver_samples_propagate_the_firmware_filter_in_si_units_and_ns() {
    const N: usize = 500;
    let raw_rate = 939i16;
    let packet = packet3([0, 0, 4096], [0, 0, raw_rate], 0, 0);
    let mut expect = default_init_sequence();
    for _ in 0..N {
        expect.extend(fifo_read(&[packet]));
    }
    let mut imu = Icm42688::new(Mock::new(&expect));
    imu.init(&mut NoopDelay::new(), Config::default())
        .expect("init");
    let t0 = 3_000_000_000u64;
    let mut filter: Option<PoseImuEkf<f32>> = None;
    let mut stamps = Vec::new();
    for k in 0..N {
        let drdy = DataReady {
            stamp_ns: t0 + 2_000_000 * k as u64,
            count: k as u32 + 1,
        };
        let mut out = [Sample {
            stamp_ns: 0,
            accel: [0.0; 3],
            gyro: [0.0; 3],
            temperature_c: 0.0,
            device_timestamp: 0,
        }];
        let read = imu.read_fifo(|| drdy, &mut out).expect("burst");
        assert_eq!(read.samples, 1);
        let sample = imu_sample(&out[0]);
        stamps.push(sample.stamp_ns);
        let f = filter.get_or_insert_with(|| {
            let init = InitialState::at_rest(sample.accel).expect("gravity");
            PoseImuEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("filter")
        });
        f.propagate(&sample).expect("every sample accepted");
    }
    imu.release().done();
    let f = filter.expect("filter");
    // ns: the stream's period is the 500 Hz ODR's; the filter stands at the previous sample.
    assert_eq!(f.imu_period_ns(), Some(2_000_000));
    assert_eq!(f.time_ns(), stamps[N - 2]);
    // rad/s: the yaw is the rate times the time; m/s^2: the IMU stays at rest.
    let rate = f64::from(raw_rate) * 1000.0 / 32768.0 * std::f64::consts::PI / 180.0;
    let expected_yaw = rate * (stamps[N - 2] - stamps[0]) as f64 * 1e-9;
    let (roll, pitch, yaw) = f.imu().rotation.euler_angles();
    println!(
        "yaw {yaw:.6} rad (expected {expected_yaw:.6}), roll {roll:.2e}, pitch {pitch:.2e}, velocity {:.2e} m/s",
        f.imu().velocity.norm()
    );
    assert!((f64::from(yaw) - expected_yaw).abs() < 1e-3);
    assert!(roll.abs() < 1e-4 && pitch.abs() < 1e-4);
    // 1 g = 9.80665 m/s^2 (the datasheet's g) against the estimator's 9.81: 3.4 mm/s^2 for
    // ~1 s, plus f32 rounding.
    assert!(f.imu().velocity.norm() < 1e-2);
}
