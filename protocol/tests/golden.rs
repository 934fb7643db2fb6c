//! Exact bytes of the wire format (docs/protocol.md): any change here is a protocol change
//! and needs a new `VERSION`.

use msreg_protocol::{
    cobs, crc, frame, Ack, AckStatus, Anchor, Bounded, CameraDistortion, CameraProjection,
    CameraSetup, Config, Corner, CornerSet, Deframer, DeviceMsg, ErrorKind, ErrorReport,
    FrameError, Gate, Hello, HostMsg, ImuBatch, ImuNoise, ImuPrior, ImuSample, ImuStart,
    MonitorSetup, Packet, Pose, Pushed, RelativePose, RestPrior, SensorPrior, SensorSet,
    TargetPose, TimeBase, TimeSyncReply, TimeSyncRequest, UpdateDiagnostic, UpdateKind,
    CORNER_SET_MAX, DEVICE_FRAME_MAX, HOST_FRAME_MAX, IMU_BATCH_MAX,
};

fn host_frame(seq: u32, msg: &HostMsg) -> Vec<u8> {
    let mut out = [0u8; HOST_FRAME_MAX];
    let n = frame::encode(seq, msg, &mut out).expect("fits HOST_FRAME_MAX");
    out[..n].to_vec()
}

fn device_frame(seq: u32, msg: &DeviceMsg) -> Vec<u8> {
    let mut out = [0u8; DEVICE_FRAME_MAX];
    let n = frame::encode(seq, msg, &mut out).expect("fits DEVICE_FRAME_MAX");
    out[..n].to_vec()
}

fn decode_host(bytes: &[u8]) -> Result<Packet<HostMsg>, FrameError> {
    let mut buf = bytes.to_vec();
    let last = buf.pop();
    assert_eq!(last, Some(0), "frame ends with the delimiter");
    frame::decode::<HostMsg>(&mut buf)
}

#[test]
fn crc16_matches_the_ccitt_false_check_value() {
    assert_eq!(crc::crc16(b"123456789"), 0x29B1);
    assert_eq!(crc::crc16(&[]), 0xFFFF);
}

#[test]
fn anchor_frame_has_exact_bytes() {
    // seq 7, variant 3 (Anchor), stamp 1, sensor 0 (a zero: COBS code 4 ends the first
    // block), CRC 0xbf8c little-endian in a block of code 3, delimiter.
    let bytes = host_frame(
        7,
        &HostMsg::Anchor(Anchor {
            stamp_ns: 1,
            sensor: 0,
        }),
    );
    assert_eq!(bytes, [0x04, 0x07, 0x03, 0x01, 0x03, 0x8c, 0xbf, 0x00]);
    let packet = decode_host(&bytes).expect("decodes");
    assert_eq!(packet.seq, 7);
    assert_eq!(
        packet.msg,
        HostMsg::Anchor(Anchor {
            stamp_ns: 1,
            sensor: 0,
        })
    );
}

#[test]
fn hello_frame_has_exact_bytes() {
    let hello = Hello {
        version: 1,
        max_frame: 512,
        rx_buffer: 4096,
    };
    let bytes = host_frame(1, &HostMsg::Hello(hello));
    // seq 1, variant 0 (a zero: COBS code 2 ends the first block), 1, 512 = 80 04,
    // 4096 = 80 20, CRC.
    assert_eq!(
        bytes,
        [0x02, 0x01, 0x08, 0x01, 0x80, 0x04, 0x80, 0x20, 0xfc, 0xdd, 0x00]
    );
    assert_eq!(
        decode_host(&bytes).expect("decodes").msg,
        HostMsg::Hello(hello)
    );
}

#[test]
fn imu_batch_frame_has_exact_bytes() {
    let sample = |offset_ns| ImuSample {
        offset_ns,
        gyro: [0.0, 0.5, -1.0],
        accel: [0.0, 0.0, 9.81],
    };
    let samples: Bounded<ImuSample, IMU_BATCH_MAX> =
        [sample(0), sample(2_500_000)].into_iter().collect();
    let msg = HostMsg::ImuBatch(ImuBatch {
        base_stamp_ns: 1_700_000_000_000_000_000,
        samples,
    });
    let bytes = host_frame(300, &msg);
    #[rustfmt::skip]
    let expected = [
        0x0e, 0xac, 0x02, 0x02, 0x80, 0x80, 0xa8, 0xb1, 0xe3, 0x9f, 0xe7, 0xcb, 0x17, 0x02,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x02, 0x3f, 0x01, 0x03, 0x80, 0xbf, 0x01,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x09, 0xc3, 0xf5, 0x1c, 0x41, 0xa0, 0xcb, 0x98,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x02, 0x3f, 0x01, 0x03, 0x80, 0xbf, 0x01,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x07, 0xc3, 0xf5, 0x1c, 0x41, 0x8f, 0xa0, 0x00,
    ];
    assert_eq!(bytes, expected);
    assert_eq!(decode_host(&bytes).expect("decodes").msg, msg);
}

#[test]
fn device_frames_have_exact_bytes() {
    let ack = DeviceMsg::Ack(Ack {
        seq: 300,
        status: AckStatus::Duplicate,
    });
    assert_eq!(
        device_frame(9, &ack),
        [0x08, 0x09, 0x01, 0xac, 0x02, 0x01, 0x7a, 0x71, 0x00]
    );
    let report = DeviceMsg::ErrorReport(ErrorReport {
        kind: ErrorKind::Crc,
        count: 3,
        seq: 0,
        stamp_ns: 0,
    });
    assert_eq!(
        device_frame(10, &report),
        [0x05, 0x0a, 0x05, 0x01, 0x03, 0x01, 0x03, 0xa1, 0x84, 0x00]
    );
}

#[test]
fn a_flipped_bit_is_a_crc_error() {
    let mut bytes = host_frame(
        7,
        &HostMsg::Anchor(Anchor {
            stamp_ns: 1,
            sensor: 0,
        }),
    );
    bytes[3] ^= 0x10;
    assert_eq!(decode_host(&bytes), Err(FrameError::Crc));
}

#[test]
fn a_truncated_frame_is_a_framing_error() {
    let bytes = host_frame(
        7,
        &HostMsg::Anchor(Anchor {
            stamp_ns: 1,
            sensor: 0,
        }),
    );
    let mut cut = bytes[..3].to_vec();
    assert_eq!(frame::decode::<HostMsg>(&mut cut), Err(FrameError::Framing));
}

#[test]
fn an_unknown_variant_is_a_decode_error() {
    // seq 1, variant 99, valid CRC.
    let body = [0x01u8, 99];
    let mut raw = body.to_vec();
    raw.extend_from_slice(&crc::crc16(&body).to_le_bytes());
    let mut enc = [0u8; 16];
    let n = cobs::encode(&raw, &mut enc).expect("fits");
    assert_eq!(
        frame::decode::<HostMsg>(&mut enc[..n]),
        Err(FrameError::Decode)
    );
}

#[test]
fn a_batch_longer_than_its_bound_is_a_decode_error() {
    // A sequence length of IMU_BATCH_MAX + 1 with no items behind it.
    let body = [0x01u8, 0x02, 0x01, (IMU_BATCH_MAX + 1) as u8];
    let mut raw = body.to_vec();
    raw.extend_from_slice(&crc::crc16(&body).to_le_bytes());
    let mut enc = [0u8; 16];
    let n = cobs::encode(&raw, &mut enc).expect("fits");
    assert_eq!(
        frame::decode::<HostMsg>(&mut enc[..n]),
        Err(FrameError::Decode)
    );
}

#[test]
fn deframer_splits_frames_and_drops_oversize_ones() {
    let frame_a = host_frame(1, &HostMsg::GetStatus);
    let mut stream = vec![0u8, 0u8]; // leading delimiters resynchronise
    stream.extend_from_slice(&[0x55; 40]);
    stream.push(0);
    stream.extend_from_slice(&frame_a);
    let mut deframer = Deframer::<16>::new();
    let mut events = Vec::new();
    for b in stream {
        match deframer.push(b) {
            Pushed::Pending => {}
            Pushed::Oversize => events.push("oversize".to_string()),
            Pushed::Frame(f) => events.push(format!("{:?}", frame::decode::<HostMsg>(f))),
        }
    }
    assert_eq!(
        events,
        [
            "oversize".to_string(),
            format!(
                "{:?}",
                Ok::<_, FrameError>(Packet {
                    seq: 1,
                    msg: HostMsg::GetStatus
                })
            )
        ]
    );
}

#[test]
fn cobs_handles_runs_of_254_and_more_nonzero_bytes() {
    for len in [253usize, 254, 255, 508, 600] {
        let input: Vec<u8> = (0..len).map(|i| (i % 255 + 1) as u8).collect();
        let mut enc = vec![0u8; cobs::max_encoded_len(len)];
        let n = cobs::encode(&input, &mut enc).expect("fits the bound");
        assert!(!enc[..n].contains(&0));
        let m = cobs::decode_in_place(&mut enc[..n]).expect("decodes");
        assert_eq!(&enc[..m], &input[..], "len {len}");
    }
}

/// The body of a frame (COBS and CRC removed), to spell out its fields.
fn body_of(frame_bytes: &[u8]) -> Vec<u8> {
    let mut buf = frame_bytes[..frame_bytes.len() - 1].to_vec();
    let n = cobs::decode_in_place(&mut buf).expect("COBS");
    buf.truncate(n - 2);
    buf
}

fn le(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn target_pose_frame_has_exact_bytes() {
    let msg = HostMsg::TargetPose(TargetPose {
        stamp_ns: 1_000,
        t_cam_target: Pose {
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
            translation_m: [0.0, 0.0, 1.5],
        },
        sigma_rotation_rad: 0.5,
        sigma_position_m: 0.25,
    });
    let bytes = host_frame(2, &msg);
    // seq 2, variant 6, stamp 1000 = e8 07, 7 + 2 f32.
    let mut body = vec![0x02, 0x06, 0xe8, 0x07];
    body.extend(le(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.5, 0.5, 0.25]));
    assert_eq!(body_of(&bytes), body);
    #[rustfmt::skip]
    let expected = [
        0x05, 0x02, 0x06, 0xe8, 0x07, 0x01, 0x03, 0x80, 0x3f, 0x01, 0x01, 0x01, 0x01, 0x01,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01,
        0x01, 0x01, 0x03, 0xc0, 0x3f, 0x01, 0x01, 0x02, 0x3f, 0x01, 0x05, 0x80, 0x3e, 0x59,
        0x4a, 0x00,
    ];
    assert_eq!(bytes, expected);
    assert_eq!(decode_host(&bytes).expect("decodes").msg, msg);
}

#[test]
fn corner_set_frame_has_exact_bytes() {
    let corners: Bounded<Corner, CORNER_SET_MAX> = [
        Corner {
            point_in_target_m: [0.0, 0.0, 0.0],
            pixel: [320.5, 240.25],
        },
        Corner {
            point_in_target_m: [0.04, 0.08, 0.0],
            pixel: [350.0, 270.0],
        },
    ]
    .into_iter()
    .collect();
    let msg = HostMsg::CornerSet(CornerSet {
        stamp_ns: 5,
        corners,
    });
    let bytes = host_frame(3, &msg);
    // seq 3, variant 7, stamp 5, 2 corners of 5 f32.
    let mut body = vec![0x03, 0x07, 0x05, 0x02];
    body.extend(le(&[
        0.0, 0.0, 0.0, 320.5, 240.25, 0.04, 0.08, 0.0, 350.0, 270.0,
    ]));
    assert_eq!(body_of(&bytes), body);
    #[rustfmt::skip]
    let expected = [
        0x05, 0x03, 0x07, 0x05, 0x02, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01,
        0x01, 0x01, 0x01, 0x04, 0x40, 0xa0, 0x43, 0x0c, 0x40, 0x70, 0x43, 0x0a, 0xd7, 0x23,
        0x3d, 0x0a, 0xd7, 0xa3, 0x3d, 0x01, 0x01, 0x01, 0x01, 0x01, 0x03, 0xaf, 0x43, 0x01,
        0x05, 0x87, 0x43, 0x71, 0x82, 0x00,
    ];
    assert_eq!(bytes, expected);
    assert_eq!(decode_host(&bytes).expect("decodes").msg, msg);
}

#[test]
fn camera_imu_config_has_exact_bytes() {
    let camera = CameraSetup {
        projection: CameraProjection::Omni { xi: 0.5 },
        intrinsics: [400.0, 400.0, 376.0, 240.0],
        distortion: CameraDistortion::RadTan([0.25, 0.0, 0.0, 0.0, 0.0]),
        resolution: [752, 480],
        pixel_sigma: 0.125,
    };
    let msg = HostMsg::Config(Config {
        sensors: SensorSet::CameraImu(camera),
        imu_noise: ImuNoise {
            gyro_noise_density: 0.0,
            accel_noise_density: 0.0,
            gyro_random_walk: 0.0,
            accel_random_walk: 0.0,
        },
        gate: Gate::P999,
        max_imu_gap_ns: 0,
        imu_prior: ImuPrior::AtRest(RestPrior {
            accel_mean: [0.0; 3],
            gyro_bias: [0.0; 3],
            sigma_orientation_rad: 0.0,
            sigma_velocity_m_s: 0.0,
        }),
        sensor: zero_prior(),
        zero_velocity_until_ns: 0,
        zero_velocity_every: 0,
        estimate_period_ns: 0,
    });
    let bytes = host_frame(1, &msg);
    // seq 1, variant 1 (Config), sensors variant 1 (CameraImu), projection 1 (Omni) + xi,
    // intrinsics, distortion 1 (RadTan) + 5 f32, 752 = f0 05, 480 = e0 03, pixel sigma,
    // then the pose-IMU fields (all zero: gate P999 = variant 4).
    let mut body = vec![0x01, 0x01, 0x01, 0x01];
    body.extend(le(&[0.5, 400.0, 400.0, 376.0, 240.0]));
    body.push(0x01);
    body.extend(le(&[0.25, 0.0, 0.0, 0.0, 0.0]));
    body.extend([0xf0, 0x05, 0xe0, 0x03]);
    body.extend(le(&[0.125]));
    body.extend(le(&[0.0; 4]));
    body.extend([0x04, 0x00, 0x00]);
    body.extend(le(&[0.0; 8]));
    body.extend(le(&[0.0; 7]));
    body.extend(le(&[0.0; 4]));
    body.extend([0x00, 0x00, 0x00]);
    assert_eq!(body_of(&bytes), body);
    // COBS turns each zero into a block code (no block reaches 254 bytes): one leading code
    // byte, the CRC and the delimiter are all it adds.
    assert_eq!(bytes.len(), 1 + body.len() + 2 + 1);
    assert_eq!(
        crc::crc16(&body).to_le_bytes(),
        [bytes[bytes.len() - 3], bytes[bytes.len() - 2]]
    );
    assert_eq!(decode_host(&bytes).expect("decodes").msg, msg);
}

#[test]
fn reprojection_diagnostic_and_new_faults_have_exact_bytes() {
    let diag = DeviceMsg::UpdateDiagnostic(UpdateDiagnostic {
        stamp_ns: 1,
        kind: UpdateKind::Reprojection,
        dof: 84,
        nis: 0.0,
        threshold: 0.0,
        accepted: true,
        sensor: Some(0),
    });
    // seq 4, variant 3, stamp 1, kind 2, dof 84 = 0x54, two zero f32, true, Some(0).
    let expected_body = [
        0x04, 0x03, 0x01, 0x02, 0x54, 0, 0, 0, 0, 0, 0, 0, 0, 0x01, 0x01, 0x00,
    ];
    assert_eq!(body_of(&device_frame(4, &diag)), expected_body);
    for (kind, index) in [
        (ErrorKind::TargetNotInitialized, 21u8),
        (ErrorKind::NotProjectable, 22),
        (ErrorKind::WrongSensorSet, 23),
    ] {
        let report = DeviceMsg::ErrorReport(ErrorReport {
            kind,
            count: 1,
            seq: 2,
            stamp_ns: 3,
        });
        assert_eq!(
            body_of(&device_frame(5, &report)),
            [0x05, 0x05, index, 0x01, 0x02, 0x03]
        );
        assert_eq!(ErrorKind::ALL[usize::from(index)], kind);
    }
}

// Buffer sizes come from MaxSize: one full IMU batch (tag, u64 base, length, 16 x (u32
// offset + 6 f32)) and one full corner set (tag, u64 stamp, length, 48 x 5 f32) fit, and the
// frames stay small enough for the device's buffers (a quarter of its 4 KiB receive ring).
const _: () = assert!(HOST_FRAME_MAX >= 2 + 10 + 1 + IMU_BATCH_MAX * 29);
const _: () = assert!(HOST_FRAME_MAX >= 2 + 10 + 1 + CORNER_SET_MAX * 20);
const _: () = assert!(HOST_FRAME_MAX <= 1024);
const _: () = assert!(DEVICE_FRAME_MAX <= 256);

fn zero_prior() -> SensorPrior {
    SensorPrior {
        extrinsic: Pose::default(),
        sigma_rotation_rad: 0.0,
        sigma_translation_m: 0.0,
        time_offset_s: 0.0,
        sigma_time_offset_s: 0.0,
    }
}

#[test]
fn monitor_config_has_exact_bytes() {
    let msg = HostMsg::Config(Config {
        sensors: SensorSet::Monitor(MonitorSetup {
            pose1: SensorPrior {
                sigma_rotation_rad: 0.5,
                ..zero_prior()
            },
            hold_translation_axis: Some([0.0, 0.0, 1.0]),
            step_forgetting: 0.25,
            resolvable_step_factor: f32::INFINITY,
            step_confidence: Gate::P99999,
        }),
        imu_noise: ImuNoise {
            gyro_noise_density: 0.0,
            accel_noise_density: 0.0,
            gyro_random_walk: 0.0,
            accel_random_walk: 0.0,
        },
        gate: Gate::P99,
        max_imu_gap_ns: 0,
        imu_prior: ImuPrior::State(ImuStart {
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
            position_m: [0.0; 3],
            velocity_m_s: [2.0, 0.0, 0.0],
            gyro_bias_rad_s: [0.0; 3],
            accel_bias_m_s2: [0.0; 3],
            sigmas: [0.5; 5],
        }),
        sensor: zero_prior(),
        zero_velocity_until_ns: 0,
        zero_velocity_every: 0,
        estimate_period_ns: 0,
    });
    let bytes = host_frame(1, &msg);
    // seq 1, variant 1 (Config), sensors variant 2 (Monitor): pose1's prior (pose, 4 f32),
    // Some (1) + axis, forgetting, factor, step confidence P99999 = 6; noise, gate P99 = 2, gap 0, imu prior variant 1
    // (State) + 4 + 4 x 3 + 5 f32, sensor 0's prior, zero-velocity until 0, every 0, period 0.
    let mut body = vec![0x01, 0x01, 0x02];
    body.extend(le(&[0.0; 7]));
    body.extend(le(&[0.5, 0.0, 0.0, 0.0]));
    body.push(0x01);
    body.extend(le(&[0.0, 0.0, 1.0, 0.25, f32::INFINITY]));
    body.push(0x06);
    body.extend(le(&[0.0; 4]));
    body.extend([0x02, 0x00, 0x01]);
    body.extend(le(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0]));
    body.extend(le(&[0.0; 6]));
    body.extend(le(&[0.5; 5]));
    body.extend(le(&[0.0; 11]));
    body.extend([0x00, 0x00, 0x00]);
    assert_eq!(body_of(&bytes), body);
    assert_eq!(decode_host(&bytes).expect("decodes").msg, msg);
}

#[test]
fn odometry_and_alarms_carry_their_sensor() {
    let anchor = HostMsg::Anchor(Anchor {
        stamp_ns: 1,
        sensor: 1,
    });
    assert_eq!(body_of(&host_frame(7, &anchor)), [0x07, 0x03, 0x01, 0x01]);
    let increment = HostMsg::RelativePose(RelativePose {
        stamp_from_ns: 1,
        stamp_to_ns: 2,
        delta: Pose::default(),
        sigma_rotation_rad: [0.0; 3],
        sigma_translation_m: [0.0; 3],
        sensor: 1,
    });
    // seq 8, variant 4, stamps, 7 + 6 f32, sensor 1.
    let mut body = vec![0x08, 0x04, 0x01, 0x02];
    body.extend(le(&[0.0; 13]));
    body.push(0x01);
    assert_eq!(body_of(&host_frame(8, &increment)), body);
    let alarm = DeviceMsg::HealthAlarm(msreg_protocol::HealthAlarm {
        stamp_ns: 3,
        kind: msreg_protocol::AlarmKind::RotationStep,
        statistic: 0.0,
        step: [0.0; 3],
        sensor: 1,
    });
    // seq 9, variant 4, stamp 3, kind 0, 4 f32, sensor 1.
    let mut body = vec![0x09, 0x04, 0x03, 0x00];
    body.extend(le(&[0.0; 4]));
    body.push(0x01);
    assert_eq!(body_of(&device_frame(9, &alarm)), body);
    let zupt = DeviceMsg::UpdateDiagnostic(UpdateDiagnostic {
        stamp_ns: 1,
        kind: UpdateKind::ZeroVelocity,
        dof: 3,
        nis: 0.0,
        threshold: 0.0,
        accepted: true,
        sensor: None,
    });
    // A zero-velocity update belongs to no sensor: None = 0.
    assert_eq!(
        body_of(&device_frame(4, &zupt)),
        [0x04, 0x03, 0x01, 0x01, 0x03, 0, 0, 0, 0, 0, 0, 0, 0, 0x01, 0x00]
    );
}

#[test]
fn time_sync_frames_have_exact_bytes() {
    // v5 appended one variant to each direction; every earlier index is unchanged (pinned
    // by the tests above), so a v4 frame decodes the same under v5.
    let request = HostMsg::TimeSync(TimeSyncRequest { t1_ns: 1_000 });
    // seq 5, variant 8 (TimeSync), t1 1000 = e8 07, CRC 0x78d8.
    let bytes = host_frame(5, &request);
    assert_eq!(bytes, [0x07, 0x05, 0x08, 0xe8, 0x07, 0xd8, 0x78, 0x00]);
    assert_eq!(decode_host(&bytes).expect("decodes").msg, request);
    let reply = DeviceMsg::TimeSync(TimeSyncReply {
        t1_ns: 1_000,
        t2_ns: 300,
        t3_ns: 301,
        time_base: TimeBase::DeviceClock,
    });
    // seq 6, variant 7 (TimeSync), t1 e8 07, t2 300 = ac 02, t3 301 = ad 02, DeviceClock 1,
    // CRC 0x0344.
    let bytes = device_frame(6, &reply);
    assert_eq!(
        bytes,
        [0x0c, 0x06, 0x07, 0xe8, 0x07, 0xac, 0x02, 0xad, 0x02, 0x01, 0x44, 0x03, 0x00]
    );
    let mut buf = bytes[..bytes.len() - 1].to_vec();
    assert_eq!(
        frame::decode::<DeviceMsg>(&mut buf).expect("decodes").msg,
        reply
    );
    // HostStamps is variant 0: zeros become COBS codes.
    let link = DeviceMsg::TimeSync(TimeSyncReply {
        t1_ns: 1,
        t2_ns: 0,
        t3_ns: 0,
        time_base: TimeBase::HostStamps,
    });
    assert_eq!(
        device_frame(6, &link),
        [0x04, 0x06, 0x07, 0x01, 0x01, 0x01, 0x03, 0x91, 0x92, 0x00]
    );
}

#[test]
fn protocol_version_is_five_since_time_sync() {
    assert_eq!(msreg_protocol::VERSION, 5);
}
