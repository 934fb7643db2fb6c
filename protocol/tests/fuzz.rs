//! Decoder fuzzing (proptest): arbitrary and corrupted byte streams never panic, memory stays
//! the deframer's fixed buffer, and valid packets survive the round trip.

use msreg_protocol::{
    frame, Anchor, Bounded, Corner, CornerSet, Deframer, DeviceMsg, HostMsg, ImuBatch, ImuSample,
    Pose, Pushed, RelativePose, TargetPose, CORNER_SET_MAX, HOST_FRAME_MAX, IMU_BATCH_MAX,
};
use proptest::prelude::*;

fn drain(deframer: &mut Deframer<HOST_FRAME_MAX>, bytes: &[u8]) -> (usize, usize) {
    let (mut ok, mut bad) = (0, 0);
    for &b in bytes {
        if let Pushed::Frame(f) = deframer.push(b) {
            match frame::decode::<HostMsg>(f) {
                Ok(_) => ok += 1,
                Err(_) => bad += 1,
            }
        }
    }
    (ok, bad)
}

fn f32_any() -> impl Strategy<Value = f32> {
    prop_oneof![
        any::<f32>(),
        Just(f32::NAN),
        Just(f32::INFINITY),
        -100.0f32..100.0
    ]
}

fn imu_batch() -> impl Strategy<Value = HostMsg> {
    (
        any::<u64>(),
        prop::collection::vec(
            (
                any::<u32>(),
                [f32_any(), f32_any(), f32_any()],
                [f32_any(), f32_any(), f32_any()],
            ),
            0..=IMU_BATCH_MAX,
        ),
    )
        .prop_map(|(base, s)| {
            let samples: Bounded<ImuSample, IMU_BATCH_MAX> = s
                .into_iter()
                .map(|(offset_ns, gyro, accel)| ImuSample {
                    offset_ns,
                    gyro,
                    accel,
                })
                .collect();
            HostMsg::ImuBatch(ImuBatch {
                base_stamp_ns: base,
                samples,
            })
        })
}

fn relative_pose() -> impl Strategy<Value = HostMsg> {
    (
        any::<u64>(),
        any::<u64>(),
        [f32_any(), f32_any(), f32_any(), f32_any()],
        any::<u8>(),
    )
        .prop_map(|(a, b, q, sensor)| {
            HostMsg::RelativePose(RelativePose {
                stamp_from_ns: a,
                stamp_to_ns: b,
                delta: Pose {
                    rotation_wxyz: q,
                    translation_m: [q[1], q[2], q[3]],
                },
                sigma_rotation_rad: [q[0]; 3],
                sigma_translation_m: [q[3]; 3],
                sensor,
            })
        })
}

fn corner_set() -> impl Strategy<Value = HostMsg> {
    (
        any::<u64>(),
        prop::collection::vec(
            ([f32_any(), f32_any(), f32_any()], [f32_any(), f32_any()]),
            0..=CORNER_SET_MAX,
        ),
    )
        .prop_map(|(stamp_ns, c)| {
            HostMsg::CornerSet(CornerSet {
                stamp_ns,
                corners: c
                    .into_iter()
                    .map(|(point_in_target_m, pixel)| Corner {
                        point_in_target_m,
                        pixel,
                    })
                    .collect(),
            })
        })
}

fn target_pose() -> impl Strategy<Value = HostMsg> {
    (any::<u64>(), [f32_any(), f32_any(), f32_any(), f32_any()]).prop_map(|(stamp_ns, q)| {
        HostMsg::TargetPose(TargetPose {
            stamp_ns,
            t_cam_target: Pose {
                rotation_wxyz: q,
                translation_m: [q[3], q[2], q[1]],
            },
            sigma_rotation_rad: q[0],
            sigma_position_m: q[1],
        })
    })
}

fn host_msg() -> impl Strategy<Value = HostMsg> {
    prop_oneof![
        imu_batch(),
        relative_pose(),
        corner_set(),
        target_pose(),
        (any::<u64>(), any::<u8>())
            .prop_map(|(stamp_ns, sensor)| HostMsg::Anchor(Anchor { stamp_ns, sensor })),
        Just(HostMsg::GetStatus),
        any::<u64>().prop_map(|t1_ns| HostMsg::TimeSync(msreg_protocol::TimeSyncRequest { t1_ns })),
    ]
}

fn same_bits(a: &HostMsg, b: &HostMsg) -> bool {
    // NaN != NaN: compare the encodings instead.
    let (mut x, mut y) = ([0u8; HOST_FRAME_MAX], [0u8; HOST_FRAME_MAX]);
    let (n, m) = (
        frame::encode(0, a, &mut x).expect("fits"),
        frame::encode(0, b, &mut y).expect("fits"),
    );
    x[..n] == y[..m]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..4096)) {
        let mut deframer = Deframer::<HOST_FRAME_MAX>::new();
        drain(&mut deframer, &bytes);
        let mut copy = bytes.clone();
        let _ = frame::decode::<HostMsg>(&mut copy);
        let _ = frame::decode::<DeviceMsg>(&mut copy);
    }

    #[test]
    fn valid_packets_round_trip(seq in any::<u32>(), msg in host_msg()) {
        let mut out = [0u8; HOST_FRAME_MAX];
        let n = frame::encode(seq, &msg, &mut out).expect("MaxSize bound holds");
        prop_assert!(!out[..n - 1].contains(&0));
        let packet = frame::decode::<HostMsg>(&mut out[..n - 1]).expect("decodes");
        prop_assert_eq!(packet.seq, seq);
        prop_assert!(same_bits(&packet.msg, &msg));
    }

    #[test]
    fn corrupted_and_interleaved_streams_recover(
        msgs in prop::collection::vec(host_msg(), 1..8),
        garbage in prop::collection::vec(any::<u8>(), 0..300),
        flip in any::<prop::sample::Index>(),
    ) {
        // garbage, a corrupted frame, then the clean frames: every clean frame after a
        // delimiter decodes.
        let mut stream = garbage.clone();
        let mut out = [0u8; HOST_FRAME_MAX];
        let n = frame::encode(1, &msgs[0], &mut out).expect("fits");
        let mut bad = out[..n].to_vec();
        let i = flip.index(n - 1);
        bad[i] = bad[i].wrapping_add(1).max(1);
        stream.extend_from_slice(&bad);
        stream.push(0);
        for (k, m) in msgs.iter().enumerate() {
            let n = frame::encode(k as u32 + 2, m, &mut out).expect("fits");
            stream.extend_from_slice(&out[..n]);
        }
        let mut deframer = Deframer::<HOST_FRAME_MAX>::new();
        let (ok, _) = drain(&mut deframer, &stream);
        prop_assert!(ok >= msgs.len());
    }
}
