//! Given / When / Then tests of the PCD reader, writer and voxel filter.
//! Float equality is exact by construction here (bit-exact round trips).
#![allow(clippy::float_cmp)]

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::*;

fn sample_cloud() -> PointCloud {
    let points = (0..50)
        .map(|i| {
            let f = f64::from(i);
            Point {
                // f32-representable so the F4 round trip is exact.
                xyz: Vector3::new(f * 0.25, -f * 0.5, 1.0 + f * 0.125),
                intensity: 10.0 + i as f32,
                t_ns: 1000 * i as u32,
                ring: (i % 128) as u16,
            }
        })
        .collect();
    PointCloud::new(points)
}

fn shared_data() -> Option<PathBuf> {
    crate::shared_data::dir_or_skip("lidar-pairs")
}

/// LZF-compresses `data` with literal runs only (valid LZF, no matches).
fn lzf_literals(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for chunk in data.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

#[test]
fn ascii_and_binary_round_trips_are_exact() {
    let cloud = sample_cloud();
    for encoding in [PcdEncoding::Ascii, PcdEncoding::Binary] {
        for xyz_f64 in [false, true] {
            let bytes = encode_pcd(&cloud, PcdWriteOptions { encoding, xyz_f64 });
            let back = parse_pcd(Path::new("mem.pcd"), &bytes).unwrap();
            assert_eq!(back, cloud, "{encoding:?} f64={xyz_f64}");
        }
    }
}

#[test]
fn f64_coordinates_round_trip_through_f8_and_a_file() {
    let mut cloud = sample_cloud();
    cloud.points[3].xyz.x = 0.1 + 1e-12;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.pcd");
    for encoding in [PcdEncoding::Ascii, PcdEncoding::Binary] {
        let options = PcdWriteOptions {
            encoding,
            xyz_f64: true,
        };
        write_pcd(&path, &cloud, options).unwrap();
        assert_eq!(read_pcd(&path).unwrap(), cloud);
    }
}

#[test]
fn binary_compressed_with_mixed_types_and_extra_fields_decodes() {
    // Given a column-major file with an ignored padding field, a U1 ring and
    // an F8 x, compressed with literal LZF runs.
    let n = 3usize;
    let mut raw = Vec::new();
    for i in 0..n {
        raw.extend_from_slice(&(i as f64 + 0.5).to_le_bytes()); // x F8
    }
    for i in 0..n {
        raw.extend_from_slice(&(-(i as f32)).to_le_bytes()); // y F4
    }
    for _ in 0..n {
        raw.extend_from_slice(&2.0f32.to_le_bytes()); // z F4
    }
    raw.extend_from_slice(&[7u8; 3 * 2]); // pad U2
    raw.extend_from_slice(&[4u8, 5, 6]); // ring U1
    let packed = lzf_literals(&raw);
    let mut bytes = format!(
        "VERSION 0.7\nFIELDS x y z _ ring\nSIZE 8 4 4 2 1\nTYPE F F F U U\nCOUNT 1 1 1 1 1\n\
         WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary_compressed\n"
    )
    .into_bytes();
    bytes.extend_from_slice(&(packed.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&(raw.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&packed);
    // When it is parsed
    let cloud = parse_pcd(Path::new("c.pcd"), &bytes).unwrap();
    // Then the values come back, missing intensity and t default to zero.
    assert_eq!(cloud.len(), 3);
    assert_eq!(cloud.points[2].xyz, Vector3::new(2.5, -2.0, 2.0));
    assert_eq!(cloud.points[1].ring, 5);
    assert_eq!(cloud.points[1].t_ns, 0);
    assert_eq!(cloud.points[1].intensity, 0.0);
}

#[test]
fn nan_points_are_dropped() {
    let text = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\nDATA ascii\n\
                1 2 3\nnan nan nan\n4 5 6\n";
    let cloud = parse_pcd(Path::new("n.pcd"), text.as_bytes()).unwrap();
    assert_eq!(cloud.len(), 2);
    assert_eq!(cloud.points[1].xyz, Vector3::new(4.0, 5.0, 6.0));
}

#[test]
fn truncated_binary_reports_expected_and_actual_bytes() {
    let bytes = encode_pcd(&sample_cloud(), PcdWriteOptions::default());
    let cut = &bytes[..bytes.len() - 7];
    let err = parse_pcd(Path::new("scan.pcd"), cut).unwrap_err();
    match &err {
        PcdError::Truncated {
            expected, actual, ..
        } => {
            assert_eq!(*expected, 50 * 22);
            assert_eq!(*actual, 50 * 22 - 7);
        }
        other => panic!("unexpected {other:?}"),
    }
    let message = err.to_string();
    assert!(
        message.starts_with("scan.pcd: truncated data: expected 1100 bytes"),
        "{message}"
    );
}

#[test]
fn truncated_ascii_and_compressed_are_errors() {
    let bytes = encode_pcd(
        &sample_cloud(),
        PcdWriteOptions {
            encoding: PcdEncoding::Ascii,
            xyz_f64: false,
        },
    );
    let text = String::from_utf8(bytes).unwrap();
    let cut: String = text.lines().take(20).map(|l| format!("{l}\n")).collect();
    assert!(matches!(
        parse_pcd(Path::new("a.pcd"), cut.as_bytes()),
        Err(PcdError::Truncated {
            expected: 50,
            actual: 9,
            ..
        })
    ));
    let compressed = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nDATA binary_compressed\n\x10\x00\x00\x00\x18\x00\x00\x00\x01";
    assert!(matches!(
        parse_pcd(Path::new("c.pcd"), compressed),
        Err(PcdError::Truncated { .. })
    ));
}

#[test]
fn bad_headers_name_the_line() {
    let cases: [(&str, usize, &str); 5] = [
        (
            "FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n0 0 0\n",
            2,
            "SIZE has 2 entries",
        ),
        (
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH one\nDATA ascii\n",
            4,
            "not a non-negative",
        ),
        (
            "# c\nFIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nDATA ascii\n",
            2,
            "`z` missing",
        ),
        (
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA zip\n",
            5,
            "DATA `zip`",
        ),
        (
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 3\nDATA ascii\n",
            5,
            "POINTS 3",
        ),
    ];
    for (text, line, needle) in cases {
        match parse_pcd(Path::new("h.pcd"), text.as_bytes()) {
            Err(e @ PcdError::Header { .. }) => {
                let message = e.to_string();
                assert!(message.starts_with(&format!("h.pcd:{line}: ")), "{message}");
                assert!(message.contains(needle), "{message}");
            }
            other => panic!("{text:?}: unexpected {other:?}"),
        }
    }
}

#[test]
fn unsupported_type_is_named() {
    let text = "FIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nWIDTH 1\nDATA ascii\n0 0 0\n";
    let err = parse_pcd(Path::new("u.pcd"), text.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            PcdError::UnsupportedType {
                line: 3,
                kind: 'F',
                size: 2,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn zero_points_is_an_error() {
    let cloud = PointCloud::default();
    for encoding in [PcdEncoding::Ascii, PcdEncoding::Binary] {
        let bytes = encode_pcd(
            &cloud,
            PcdWriteOptions {
                encoding,
                xyz_f64: false,
            },
        );
        let err = parse_pcd(Path::new("z.pcd"), &bytes).unwrap_err();
        assert!(matches!(err, PcdError::ZeroPoints { .. }), "{err:?}");
    }
    let all_nan = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\nnan 0 0\n";
    let err = parse_pcd(Path::new("z.pcd"), all_nan.as_bytes()).unwrap_err();
    assert!(err.to_string().contains("non-finite"), "{err}");
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let err = read_pcd("/nonexistent/dir/x.pcd").unwrap_err();
    assert!(
        err.to_string().starts_with("/nonexistent/dir/x.pcd: "),
        "{err}"
    );
}

#[test]
fn voxel_filter_keeps_one_centroid_per_voxel() {
    // Given 8 points in voxel (0,0,0) and 1 in voxel (-1,0,0) of side 1 m
    let mut points: Vec<Point> = (0..8)
        .map(|i| Point {
            xyz: Vector3::new(0.1 * f64::from(i), 0.5, 0.5),
            intensity: 2.0,
            t_ns: 10,
            ring: 3,
        })
        .collect();
    points.push(Point::from_xyz(Vector3::new(-0.5, 0.2, 0.2)));
    // When filtered
    let out = voxel_downsample(&PointCloud::new(points), 1.0);
    // Then two centroids remain, in first-hit order
    assert_eq!(out.len(), 2);
    assert!((out.points[0].xyz - Vector3::new(0.35, 0.5, 0.5)).norm() < 1e-12);
    assert_eq!(out.points[0].intensity, 2.0);
    assert_eq!(out.points[0].ring, 3);
    assert_eq!(out.points[1].xyz, Vector3::new(-0.5, 0.2, 0.2));
}

#[test]
fn both_real_lidar_pairs_are_read() {
    let Some(dir) = shared_data() else { return };
    let cases = [
        ("outdoor-fast-gicp/251370668.pcd", 69088),
        ("outdoor-fast-gicp/251371071.pcd", 69792),
        ("room-pcl/room_scan1.pcd", 112586),
        ("room-pcl/room_scan2.pcd", 112624),
    ];
    for (file, header_points) in cases {
        let cloud = read_pcd(dir.join(file)).unwrap();
        // NaN returns may be dropped, nothing else.
        assert!(
            cloud.len() <= header_points && cloud.len() > header_points * 9 / 10,
            "{file}: {}",
            cloud.len()
        );
        let max_range = cloud
            .points
            .iter()
            .map(|p| p.xyz.norm())
            .fold(0.0, f64::max);
        assert!(
            max_range > 3.0 && max_range < 500.0,
            "{file}: max range {max_range}"
        );
        let down = voxel_downsample(&cloud, 0.2);
        assert!(
            down.len() > 1000 && down.len() < cloud.len(),
            "{file}: {}",
            down.len()
        );
    }
}
