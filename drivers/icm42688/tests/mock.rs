//! The driver against embedded-hal-mock SPI transactions written from the datasheet's
//! register map (tests/common): initialisation, FIFO bursts, scaling, self-test, time stamps.

mod common;

use std::cell::Cell;

use common::{
    configure_sequence, default_init_sequence, fifo_read, packet3, packet_with_header, r,
    reset_sequence, w, T,
};
use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as Delay};
use embedded_hal_mock::eh1::spi::Mock;
use msreg_icm42688::{
    AccelRange, Config, DataReady, Error, GyroRange, Icm42688, Odr, Sample, UiFilter,
};

const G: f64 = 9.806_65;

fn zero_sample() -> Sample {
    Sample {
        stamp_ns: 0,
        accel: [0.0; 3],
        gyro: [0.0; 3],
        temperature_c: 0.0,
        device_timestamp: 0,
    }
}

/// A driver initialised with `Config::default()`, with `more` expected after the init.
fn initialised(more: &[T]) -> Icm42688<Mock<u8>> {
    let mut expect = default_init_sequence();
    expect.extend_from_slice(more);
    let mut imu = Icm42688::new(Mock::new(&expect));
    imu.init(&mut NoopDelay::new(), Config::default())
        .expect("init");
    imu
}

fn finish(imu: Icm42688<Mock<u8>>) {
    imu.release().done();
}

#[test]
fn init_writes_the_datasheet_sequence_and_waits_as_it_asks() {
    let mut imu = Icm42688::new(Mock::new(&default_init_sequence()));
    // 1 ms after the soft reset, 200 us after turning the sensors on.
    let mut delay = CheckedDelay::new(&[Delay::delay_ms(1), Delay::delay_us(200)]);
    imu.init(&mut delay, Config::default()).expect("init");
    delay.done();
    assert_eq!(imu.config(), Some(&Config::default()));
    finish(imu);
}

#[test]
fn a_wrong_who_am_i_stops_before_any_write() {
    let expect = [w(0x76, 0x00), r(0x75, &[0x12])].concat();
    let mut imu = Icm42688::new(Mock::new(&expect));
    let e = imu.init(&mut NoopDelay::new(), Config::default());
    assert_eq!(e, Err(Error::WrongDevice { found: 0x12 }));
    assert_eq!(imu.config(), None);
    finish(imu);
}

#[test]
fn a_reset_that_does_not_complete_is_an_error() {
    let expect = [
        w(0x76, 0x00),
        r(0x75, &[0x47]),
        w(0x11, 0x01),
        r(0x2D, &[0x00]),
    ]
    .concat();
    let mut imu = Icm42688::new(Mock::new(&expect));
    let e = imu.init(&mut NoopDelay::new(), Config::default());
    assert_eq!(e, Err(Error::ResetNotDone { int_status: 0 }));
    finish(imu);
}

#[test]
fn an_anti_alias_setting_beyond_its_bits_is_refused_before_the_bus_is_touched() {
    let config = Config {
        anti_alias: Some(msreg_icm42688::AntiAlias {
            delt: 64,
            deltsqr: 1,
            bitshift: 1,
        }),
        ..Config::default()
    };
    let mut imu = Icm42688::new(Mock::new(&[]));
    assert_eq!(
        imu.init(&mut NoopDelay::new(), config),
        Err(Error::InvalidConfig)
    );
    finish(imu);
}

#[test]
fn reading_the_fifo_before_init_is_an_error() {
    let mut imu = Icm42688::new(Mock::new(&[]));
    let mut out = [zero_sample(); 4];
    let e = imu.read_fifo(DataReady::default, &mut out);
    assert_eq!(e, Err(Error::NotInitialized));
    finish(imu);
}

/// A bus that always fails.
struct BrokenBus;

impl ErrorType for BrokenBus {
    type Error = ErrorKind;
}

impl SpiDevice for BrokenBus {
    fn transaction(&mut self, _: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
        Err(ErrorKind::ModeFault)
    }
}

#[test]
fn bus_errors_are_returned_typed() {
    let mut imu = Icm42688::new(BrokenBus);
    assert_eq!(imu.who_am_i(), Err(Error::Spi(ErrorKind::ModeFault)));
    assert_eq!(
        imu.init(&mut NoopDelay::new(), Config::default()),
        Err(Error::Spi(ErrorKind::ModeFault))
    );
}

#[test]
fn a_fifo_burst_is_parsed_scaled_and_stamped() {
    let packets = [
        packet3([100, -200, 4096], [16, -32, 64], 21, 1000),
        packet3([101, -201, 4097], [17, -33, 65], 22, 3000),
        packet3([102, -202, 4098], [18, -34, 66], -10, 5000),
    ];
    let mut imu = initialised(&fifo_read(&packets));
    let drdy = DataReady {
        stamp_ns: 1_000_000_000,
        count: 3,
    };
    let mut out = [zero_sample(); 8];
    let read = imu.read_fifo(|| drdy, &mut out).expect("read");
    assert_eq!(read.samples, 3);
    assert_eq!(read.fifo_packets, 3);
    assert_eq!(
        (read.invalid, read.corrupt_header, read.bad_count),
        (0, None, None)
    );
    // +-8 g: 4096 LSB/g; +-1000 deg/s: 32.8 LSB/(deg/s) (32768 / 1000).
    let a = G / 4096.0;
    let g = 1000.0 / 32768.0 * std::f64::consts::PI / 180.0;
    for (k, s) in out[..3].iter().enumerate() {
        let i = k as f64;
        let accel = [(100.0 + i) * a, (-200.0 - i) * a, (4096.0 + i) * a];
        let gyro = [(16.0 + i) * g, (-32.0 - i) * g, (64.0 + i) * g];
        for j in 0..3 {
            assert!((f64::from(s.accel[j]) - accel[j]).abs() < 1e-6 * accel[j].abs().max(1.0));
            assert!((f64::from(s.gyro[j]) - gyro[j]).abs() < 1e-6 * gyro[j].abs().max(1e-3));
        }
        assert_eq!(s.device_timestamp, 1000 + 2000 * k as u16);
        // The newest packet is the pulse's; the others one 500 Hz period (2 ms) apart.
        assert_eq!(s.stamp_ns, 1_000_000_000 - (2 - k as u64) * 2_000_000);
    }
    // Temperature: FIFO_TEMP_DATA / 2.07 + 25.
    assert!((out[0].temperature_c - (21.0 / 2.07 + 25.0)).abs() < 1e-4);
    assert!((out[2].temperature_c - (-10.0 / 2.07 + 25.0)).abs() < 1e-4);
    finish(imu);
}

#[test]
fn an_empty_fifo_reads_only_the_count() {
    let mut imu = initialised(&fifo_read(&[]));
    let mut out = [zero_sample(); 4];
    let read = imu.read_fifo(DataReady::default, &mut out).expect("read");
    assert_eq!((read.samples, read.fifo_packets), (0, 0));
    finish(imu);
}

#[test]
fn a_burst_reads_no_more_than_the_output_holds_and_the_rest_follows() {
    let p: Vec<[u8; 16]> = (0..5).map(|k| packet3([k; 3], [k; 3], 0, 0)).collect();
    let mut expect = r(0x2E, &80u16.to_be_bytes());
    expect.extend(r(0x30, &p[..2].concat()));
    expect.extend(r(0x2E, &48u16.to_be_bytes()));
    expect.extend(r(0x30, &p[2..].concat()));
    let mut imu = initialised(&expect);
    let drdy = DataReady {
        stamp_ns: 50_000_000,
        count: 5,
    };
    let mut out = [zero_sample(); 2];
    let first = imu.read_fifo(|| drdy, &mut out).expect("read");
    assert_eq!((first.samples, first.fifo_packets), (2, 5));
    assert_eq!(out[0].stamp_ns, 50_000_000 - 4 * 2_000_000);
    assert_eq!(out[1].stamp_ns, 50_000_000 - 3 * 2_000_000);
    let mut rest = [zero_sample(); 8];
    let second = imu.read_fifo(|| drdy, &mut rest).expect("read");
    assert_eq!((second.samples, second.fifo_packets), (3, 3));
    let stamps: Vec<u64> = rest[..3].iter().map(|s| s.stamp_ns).collect();
    assert_eq!(stamps, [46_000_000, 48_000_000, 50_000_000]);
    assert_eq!(imu.stamper().resyncs(), 0);
    finish(imu);
}

#[test]
fn invalid_samples_are_skipped_and_counted_but_keep_their_time_slot() {
    let packets = [
        packet3([i16::MIN, 0, 0], [0; 3], 0, 0),
        packet3([1, 2, 3], [4, 5, i16::MIN], 0, 0),
        packet3([1, 2, 3], [4, 5, 6], 0, 0),
    ];
    let mut imu = initialised(&fifo_read(&packets));
    let drdy = DataReady {
        stamp_ns: 10_000_000,
        count: 3,
    };
    let mut out = [zero_sample(); 4];
    let read = imu.read_fifo(|| drdy, &mut out).expect("read");
    assert_eq!((read.samples, read.invalid), (1, 2));
    assert_eq!(out[0].stamp_ns, 10_000_000);
    finish(imu);
}

#[test]
fn a_corrupt_packet_stops_the_burst_flushes_the_fifo_and_re_anchors_the_stamps() {
    let good = packet3([1, 2, 3], [4, 5, 6], 0, 0);
    // 0x20: gyro only (packet 2, 8 bytes): the stream is out of step with packet 3.
    let bad = packet_with_header(0x20, [7; 3], [8; 3], 0, 0);
    let mut expect = fifo_read(&[good, bad, good]);
    expect.extend(w(0x4B, 0x02));
    // After the flush: two new packets, the pulse count went on.
    expect.extend(fifo_read(&[good, good]));
    let mut imu = initialised(&expect);
    let mut out = [zero_sample(); 4];
    let first = DataReady {
        stamp_ns: 100_000_000,
        count: 3,
    };
    let read = imu.read_fifo(|| first, &mut out).expect("read");
    assert_eq!((read.samples, read.corrupt_header), (1, Some(0x20)));
    assert_eq!(out[0].stamp_ns, 96_000_000);
    let second = DataReady {
        stamp_ns: 104_000_000,
        count: 5,
    };
    let read = imu.read_fifo(|| second, &mut out).expect("read");
    assert_eq!((read.samples, read.corrupt_header), (2, None));
    assert_eq!(
        [out[0].stamp_ns, out[1].stamp_ns],
        [102_000_000, 104_000_000]
    );
    assert_eq!(imu.stamper().resyncs(), 1);
    finish(imu);
}

#[test]
fn a_fifo_count_beyond_the_fifo_is_reported_and_flushed() {
    let expect = [r(0x2E, &[0x09, 0x00]), w(0x4B, 0x02)].concat();
    let mut imu = initialised(&expect);
    let mut out = [zero_sample(); 4];
    let read = imu.read_fifo(DataReady::default, &mut out).expect("read");
    assert_eq!((read.samples, read.bad_count), (0, Some(0x0900)));
    finish(imu);
}

/// Datasheet sensitivities (section 3.1 / 3.2): gyro LSB/(deg/s), accel LSB/g.
const GYRO_SENSITIVITY: [f64; 8] = [16.4, 32.8, 65.5, 131.0, 262.0, 524.3, 1048.6, 2097.2];
const ACCEL_SENSITIVITY: [f64; 4] = [2048.0, 4096.0, 8192.0, 16384.0];

#[test]
fn scaling_follows_every_full_scale_setting() {
    for (i, gyro_range) in GyroRange::ALL.into_iter().enumerate() {
        let accel_range = AccelRange::ALL[i % 4];
        let config = Config {
            odr: Odr::Hz1000,
            gyro_range,
            accel_range,
            gyro_filter: UiFilter::OdrDiv2,
            accel_filter: UiFilter::OdrDiv2,
            anti_alias: None,
        };
        // FS_SEL in bits 7:5, ODR 1 kHz = code 6 in bits 3:0.
        let code = |fs: usize| ((fs as u8) << 5) | 6;
        let raw = [12_000i16, -20_000, 32_767];
        let mut expect = reset_sequence();
        expect.extend(configure_sequence(code(i), code(i % 4), 0x00, None));
        expect.extend(fifo_read(&[packet3(raw, raw, 0, 0)]));
        let mut imu = Icm42688::new(Mock::new(&expect));
        imu.init(&mut NoopDelay::new(), config).expect("init");
        let mut out = [zero_sample(); 1];
        let read = imu.read_fifo(DataReady::default, &mut out).expect("read");
        assert_eq!(read.samples, 1);
        let s = &out[0];
        for (j, &lsb) in raw.iter().enumerate() {
            let v = f64::from(lsb);
            let exact_g =
                v * gyro_range.full_scale_dps() as f64 / 32768.0 * std::f64::consts::PI / 180.0;
            let exact_a = v * accel_range.full_scale_g() as f64 / 32768.0 * G;
            assert!((f64::from(s.gyro[j]) - exact_g).abs() <= 1e-6 * exact_g.abs());
            assert!((f64::from(s.accel[j]) - exact_a).abs() <= 1e-6 * exact_a.abs());
            // Against the datasheet's rounded sensitivity table: within its rounding (0.1 %).
            let table_g = v / GYRO_SENSITIVITY[i] * std::f64::consts::PI / 180.0;
            let table_a = v / ACCEL_SENSITIVITY[i % 4] * G;
            assert!(
                (f64::from(s.gyro[j]) / table_g - 1.0).abs() < 1e-3,
                "{gyro_range:?}"
            );
            assert!(
                (f64::from(s.accel[j]) / table_a - 1.0).abs() < 1e-6,
                "{accel_range:?}"
            );
        }
        finish(imu);
    }
}

/// A data-ready line: a copy per call from a script (before / after each burst).
fn script(copies: Vec<DataReady>) -> impl FnMut() -> DataReady {
    let mut it = copies.into_iter();
    move || it.next().expect("a scripted data-ready copy")
}

#[test]
fn a_missed_pulse_is_detected_and_the_stamps_re_anchor() {
    let p = packet3([1; 3], [1; 3], 0, 0);
    let expect = [fifo_read(&[p]), fifo_read(&[p, p]), fifo_read(&[p])].concat();
    let mut imu = initialised(&expect);
    let mut out = [zero_sample(); 4];
    let t = |k: u64| 1_000_000 + 2_000_000 * k;
    let c = |k: u64, n: u32| DataReady {
        stamp_ns: t(k),
        count: n,
    };
    // Packet 0 at pulse 1. Then the pulse of packet 1 is missed: the copy says pulse 2 was
    // packet 2's, the FIFO holds packets 1 and 2: the newest is one past the count.
    imu.read_fifo(script(vec![c(0, 1), c(0, 1)]), &mut out)
        .expect("read");
    assert_eq!(out[0].stamp_ns, t(0));
    imu.read_fifo(script(vec![c(2, 2), c(2, 2)]), &mut out)
        .expect("read");
    assert_eq!(imu.stamper().resyncs(), 1);
    assert_eq!([out[0].stamp_ns, out[1].stamp_ns], [t(1), t(2)]);
    imu.read_fifo(script(vec![c(3, 3), c(3, 3)]), &mut out)
        .expect("read");
    assert_eq!(out[0].stamp_ns, t(3));
    assert_eq!(imu.stamper().resyncs(), 1);
    finish(imu);
}

/// The time-stamp simulation: the IMU's oscillator runs 1 % slow (2.02 ms at a nominal
/// 500 Hz), the interrupt handler sees each pulse 3 us late with +-0.5 us of jitter, the
/// main loop reads 1-4 packets at a time, and sometimes a packet lands between the first
/// data-ready copy and the FIFO count read.
#[test]
fn stamps_follow_the_imu_clock_after_the_period_converges() {
    let period = 2_020_000u64;
    let latency = 3_000u64;
    let t0 = 5_000_000u64;
    let truth = |k: u64| t0 + k * period;
    let isr = |k: u64| truth(k) + latency + [0, 500, 250, 0, 400, 100, 300][(k % 7) as usize] - 250;
    let copy = |k: u64| DataReady {
        stamp_ns: isr(k),
        count: k as u32 + 1,
    };
    let packet = packet3([0, 0, 2048], [0; 3], 0, 0);
    let mut expect = Vec::new();
    let mut copies = Vec::new();
    let (mut read, mut k) = (0u64, 0u64);
    let mut bursts = Vec::new();
    for b in 0..400u64 {
        k += [1, 2, 1, 3, 1, 4, 2][(b % 7) as usize];
        // Every 9th burst a packet lands during the read: after the first copy.
        let landed = b % 9 == 4;
        let newest = if landed { k } else { k - 1 };
        let n = (newest + 1 - read) as usize;
        expect.extend(fifo_read(&vec![packet; n]));
        copies.push(copy(k - 1));
        copies.push(copy(newest));
        bursts.push((read, n));
        read = newest + 1;
        k = read;
    }
    let mut imu = initialised(&expect);
    let mut next = script(copies);
    let (mut worst_early, mut worst_late) = (0i64, 0i64);
    let mut last = 0u64;
    for (b, &(first, n)) in bursts.iter().enumerate() {
        let mut out = [zero_sample(); 8];
        let r = imu.read_fifo(&mut next, &mut out).expect("read");
        assert_eq!(r.samples, n);
        for (i, s) in out[..n].iter().enumerate() {
            assert!(s.stamp_ns > last, "stamps increase");
            last = s.stamp_ns;
            let err = s.stamp_ns as i64 - (truth(first + i as u64) + latency) as i64;
            if b < 200 {
                worst_early = worst_early.max(err.abs());
            } else {
                worst_late = worst_late.max(err.abs());
            }
        }
    }
    let est = f64::from(imu.stamper().period_ns());
    println!(
        "period estimate {est:.1} ns (true {period}), worst stamp error: bursts 0-199 {worst_early} ns, 200-399 {worst_late} ns, resyncs {}, clamped {}",
        imu.stamper().resyncs(),
        imu.stamper().clamped()
    );
    // Measured: 2,020,000.0 ns; 293 ns after the period converged (the handler's jitter is
    // +-250 ns around its latency), 49.8 us while it converges from the nominal 2 ms.
    assert!((est - period as f64).abs() < 20.0, "period {est}");
    assert!(worst_late < 900, "stamp error {worst_late} ns");
    assert_eq!(imu.stamper().resyncs(), 0);
    assert_eq!(imu.stamper().clamped(), 0);
    finish(imu);
}

/// Factory self-test response at FS_SEL 3 for an OTP code (datasheet / TDK's reference
/// driver): 2620 x 1.01^(code - 1) LSB.
fn factory(code: u8) -> f64 {
    2620.0 * 1.01f64.powi(i32::from(code) - 1)
}

/// The self-test's bus traffic: setup, 200 reads of the 12 data bytes (0x1F) per state
/// (off, gyro self-test 0x07, accel self-test 0x78 in SELF_TEST_CONFIG 0x70), then the OTP
/// codes (bank 1 0x5F.., bank 2 0x3B..). `response` is added to the gyro (then accel)
/// outputs while actuated; every read carries a little deterministic noise.
fn self_test_traffic(gyro_response: [i16; 3], accel_response: [i16; 3], codes: [u8; 6]) -> Vec<T> {
    let base_accel = [30i16, -40, 16384];
    let base_gyro = [12i16, -7, 3];
    let reads = |gyro_add: [i16; 3], accel_add: [i16; 3]| -> Vec<T> {
        (0..200)
            .flat_map(|k: i16| {
                let noise = (k % 5) - 2;
                let mut b = Vec::new();
                for j in 0..3 {
                    b.extend((base_accel[j] + accel_add[j] + noise).to_be_bytes());
                }
                for j in 0..3 {
                    b.extend((base_gyro[j] + gyro_add[j] - noise).to_be_bytes());
                }
                r(0x1F, &b)
            })
            .collect()
    };
    [
        w(0x76, 0x00),
        w(0x4F, 0x66),
        w(0x50, 0x66),
        w(0x52, 0x44),
        w(0x4E, 0x0F),
        reads([0; 3], [0; 3]),
        w(0x70, 0x07),
        reads(gyro_response, [0; 3]),
        w(0x70, 0x00),
        w(0x70, 0x78),
        reads([0; 3], accel_response),
        w(0x70, 0x00),
        w(0x76, 0x01),
        r(0x5F, &codes[..3]),
        w(0x76, 0x02),
        r(0x3B, &codes[3..]),
        w(0x76, 0x00),
    ]
    .concat()
}

#[test]
fn self_test_passes_when_every_response_matches_its_factory_code() {
    let codes = [50, 60, 70, 40, 45, 80];
    let f = |i: usize| factory(codes[i]);
    // Responses at 100 %, 80 %, -120 % (the sign does not matter) and 140 %, 60 %, 95 %.
    let gyro = [f(0), 0.8 * f(1), -1.2 * f(2)].map(|v| v.round() as i16);
    let accel = [1.4 * f(3), 0.6 * f(4), 0.95 * f(5)].map(|v| v.round() as i16);
    let mut imu = Icm42688::new(Mock::new(&self_test_traffic(gyro, accel, codes)));
    let report = imu.self_test(&mut NoopDelay::new()).expect("self-test");
    assert!(report.passed(), "{report:?}");
    let ratios = [1.0, 0.8, 1.2, 1.4, 0.6, 0.95];
    for (a, (ratio, code)) in report
        .gyro
        .iter()
        .chain(&report.accel)
        .zip(ratios.iter().zip(codes))
    {
        assert_eq!(a.code, code);
        assert!((f64::from(a.factory_lsb) - factory(code)).abs() < 0.01 * factory(code));
        assert!((f64::from(a.ratio) - ratio).abs() < 1e-3, "{a:?}");
    }
    finish(imu);
}

#[test]
fn self_test_fails_a_weak_or_uncoded_axis_and_restores_the_configuration() {
    let codes = [50, 50, 0, 50, 50, 50];
    let f = factory(50);
    let gyro = [0.45 * f, f, f].map(|v| v.round() as i16);
    let accel = [f, 1.55 * f, f].map(|v| v.round() as i16);
    let mut expect = self_test_traffic(gyro, accel, codes);
    expect.extend(configure_sequence(0x2F, 0x2F, 0x11, Some((5, 25, 10))));
    let mut imu = initialised(&expect);
    let report = imu.self_test(&mut NoopDelay::new()).expect("self-test");
    assert!(!report.passed());
    let pass: Vec<bool> = report
        .gyro
        .iter()
        .chain(&report.accel)
        .map(|a| a.pass)
        .collect();
    // Gyro X at 45 %, gyro Z without a factory code, accel Y at 155 %.
    assert_eq!(pass, [false, true, false, true, false, true]);
    assert!(report.gyro[2].factory_lsb.abs() < f32::EPSILON);
    assert_eq!(imu.config(), Some(&Config::default()));
    finish(imu);
}

#[test]
fn self_test_without_valid_data_is_an_error() {
    let stuck: Vec<u8> = (0..6).flat_map(|_| i16::MIN.to_be_bytes()).collect();
    let mut expect = [
        w(0x76, 0x00),
        w(0x4F, 0x66),
        w(0x50, 0x66),
        w(0x52, 0x44),
        w(0x4E, 0x0F),
    ]
    .concat();
    for _ in 0..200 {
        expect.extend(r(0x1F, &stuck));
    }
    let mut imu = Icm42688::new(Mock::new(&expect));
    assert_eq!(
        imu.self_test(&mut NoopDelay::new()),
        Err(Error::SelfTestNoData)
    );
    finish(imu);
}

#[test]
fn data_ready_copies_are_taken_before_the_count_and_after_the_burst() {
    let calls = Cell::new(0);
    let mut imu = initialised(&fifo_read(&[packet3([1; 3], [1; 3], 0, 0)]));
    let mut out = [zero_sample(); 2];
    imu.read_fifo(
        || {
            calls.set(calls.get() + 1);
            DataReady {
                stamp_ns: 7,
                count: 1,
            }
        },
        &mut out,
    )
    .expect("read");
    assert_eq!(calls.get(), 2);
    finish(imu);
}
