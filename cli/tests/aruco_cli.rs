//! `msreg detect aruco` / `msreg detect blobs` end to end: CSV on a rendered image, exit 2
//! with the file named on bad input.

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::process::Command;

use msreg_host::vision::aruco::render::{render_marker, Ink};
use msreg_host::vision::aruco::Dictionary;
use msreg_host::vision::GrayImage;
use nalgebra::Vector2;

fn msreg() -> Command {
    Command::new(env!("CARGO_BIN_EXE_msreg"))
}

#[test]
fn detect_aruco_prints_csv_and_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let mut img = GrayImage::new(200, 160, 120.0);
    let corners = [
        Vector2::new(60.3, 40.2),
        Vector2::new(140.1, 45.7),
        Vector2::new(135.6, 120.4),
        Vector2::new(58.9, 115.0),
    ];
    let ink = Ink {
        black: 20.0,
        white: 230.0,
    };
    assert!(render_marker(
        &mut img,
        Dictionary::Dict4x4_50,
        17,
        &corners,
        0.3,
        ink,
        8
    ));
    // A bright spot for the blob detector.
    img.data_mut()[20 * 200 + 20] = 255.0;
    img.data_mut()[20 * 200 + 21] = 255.0;
    img.data_mut()[21 * 200 + 20] = 255.0;
    let path = dir.path().join("marker.png");
    img.to_luma8().save(&path).unwrap();

    let out = msreg()
        .args(["detect", "aruco", "--dictionary", "DICT_4X4_50"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "image,id,u0,v0,u1,v1,u2,v2,u3,v3");
    assert_eq!(lines.len(), 2, "{text}");
    let f: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(f[1], "17");
    let u0: f64 = f[2].parse().unwrap();
    let v0: f64 = f[3].parse().unwrap();
    assert!((u0 - 60.3).abs() < 0.5 && (v0 - 40.2).abs() < 0.5, "{text}");

    let out = msreg()
        .args(["detect", "blobs"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.lines().any(|l| l.contains(",20.3333,20.3333,3,")),
        "{text}"
    );

    let out = msreg()
        .args(["detect", "aruco", "--dictionary", "DICT_9X9"])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown ArUco dictionary 'DICT_9X9'"));

    let missing = dir.path().join("missing.png");
    let out = msreg()
        .args(["detect", "aruco", "--dictionary", "DICT_6X6_250"])
        .arg(&path)
        .arg(&missing)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(out.stdout.is_empty());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.png"));
}
