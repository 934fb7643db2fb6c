//! ArUco detection against OpenCV on the real marker photos of Debian's opencv-doc package
//! (docs/aruco.md). Needs the photos and OpenCV's reference CSV in /tmp:
//!
//!     cd /tmp && apt-get download opencv-doc && dpkg-deb -x opencv-doc*.deb /tmp/opencv-doc
//!     python3 -m venv /tmp/venv-aruco && /tmp/venv-aruco/bin/pip install opencv-python-headless
//!     /tmp/venv-aruco/bin/python tools/aruco_opencv_reference.py
//!     cargo test --release -p msreg-host --test aruco_opencv -- --nocapture
//!
//! tools/test.sh makes both (step "OpenCV ArUco reference") and points the paths at them
//! with `MSREG_OPENCV_DOC_HTML` and `MSREG_ARUCO_REFERENCE`. Absent, the test skips with a
//! `SKIP:` notice, and fails under CI (`msreg_host::shared_data`).

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::PathBuf;

use msreg_host::vision::aruco::{detect_markers, ArucoParams, Dictionary};
use msreg_host::vision::GrayImage;
use nalgebra::Vector2;

struct Reference {
    image: String,
    dictionary: Dictionary,
    id: usize,
    corners: [Vector2<f64>; 4],
}

fn read_reference(path: &PathBuf) -> Vec<Reference> {
    let text = std::fs::read_to_string(path).expect("reference CSV readable");
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let v: Vec<f64> = f[3..11].iter().map(|x| x.parse().unwrap()).collect();
            Reference {
                image: f[0].to_string(),
                dictionary: f[1].parse().unwrap(),
                id: f[2].parse().unwrap(),
                corners: std::array::from_fn(|i| Vector2::new(v[2 * i], v[2 * i + 1])),
            }
        })
        .collect()
}

/// Markers OpenCV decodes and msreg does not, with the reason (docs/aruco.md):
/// singlemarkersdetection.jpg is singlemarkersoriginal.jpg with OpenCV's detection drawn
/// over it; the blue "id=40" label touches marker 40, so its dark outer boundary is no
/// quadrilateral (msreg traces outer boundaries only; OpenCV lists every contour).
/// The same marker is found in the clean photo.
const KNOWN_MISSES: &[&str] = &["singlemarkersdetection.jpg DICT_6X6_250 id 40"];

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn every_marker_opencv_decodes_is_found_with_its_corners() {
    let html = PathBuf::from(
        std::env::var("MSREG_OPENCV_DOC_HTML")
            .unwrap_or_else(|_| "/tmp/opencv-doc/usr/share/doc/opencv-doc/opencv4/html".into()),
    );
    let reference = PathBuf::from(
        std::env::var("MSREG_ARUCO_REFERENCE")
            .unwrap_or_else(|_| "/tmp/aruco_reference.csv".into()),
    );
    if !msreg_host::shared_data::present_or_skip(
        &[&html, &reference],
        "tools/test.sh makes both; by hand: host/tests/aruco_opencv.rs, docs/aruco.md",
    ) {
        return;
    }
    let refs = read_reference(&reference);
    let mut groups: BTreeMap<(String, Dictionary), Vec<&Reference>> = BTreeMap::new();
    for r in &refs {
        groups
            .entry((r.image.clone(), r.dictionary))
            .or_default()
            .push(r);
    }
    let params = ArucoParams::default();
    let (mut all_errors, mut missing, mut extra) = (Vec::new(), Vec::new(), 0);
    for ((image, dict), expected) in &groups {
        let img = GrayImage::load(&html.join(image)).expect("photo loads");
        let found = detect_markers(&img, *dict, &params);
        let mut errors = Vec::new();
        for r in expected {
            let centre = r.corners.iter().sum::<Vector2<f64>>() / 4.0;
            let m = found.iter().find(|m| {
                m.id == r.id && (m.corners.iter().sum::<Vector2<f64>>() / 4.0 - centre).norm() < 5.0
            });
            match m {
                Some(m) => errors.extend(
                    m.corners
                        .iter()
                        .zip(&r.corners)
                        .map(|(a, b)| (a - b).norm()),
                ),
                None => missing.push(format!("{image} {dict} id {}", r.id)),
            }
        }
        for m in &found {
            let c = m.corners.iter().sum::<Vector2<f64>>() / 4.0;
            let known = expected.iter().any(|r| {
                r.id == m.id && (r.corners.iter().sum::<Vector2<f64>>() / 4.0 - c).norm() < 5.0
            });
            if !known {
                eprintln!("  msreg only: {image} {dict} id {} at {:.1?}", m.id, c);
                extra += 1;
            }
        }
        let max = errors.iter().copied().fold(0.0, f64::max);
        eprintln!(
            "{image} {dict}: OpenCV {} msreg {} | corner error median {:.4} px max {:.4} px",
            expected.len(),
            found.len(),
            if errors.is_empty() {
                f64::NAN
            } else {
                median(errors.clone())
            },
            max
        );
        all_errors.extend(errors);
    }
    let med = median(all_errors.clone());
    let max = all_errors.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "all: {} markers, {} corners, median {med:.4} px, max {max:.4} px, missing {:?}, extra {extra}",
        refs.len(),
        all_errors.len(),
        missing
    );
    let unexpected: Vec<&String> = missing
        .iter()
        .filter(|m| !KNOWN_MISSES.contains(&m.as_str()))
        .collect();
    assert!(
        unexpected.is_empty(),
        "OpenCV markers not found: {unexpected:?}"
    );
    // Issue 14: median within 0.1 px of OpenCV. Measured: median 0.0001 px, max 0.050 px.
    assert!(med < 0.1, "median corner difference {med} px");
    assert!(max < 0.15, "largest corner difference {max} px");
}
