//! `msreg target`'s SVGs measured: the XML is read back (a small reader here, not the
//! writer's code), every square and tag measured against the requested size, the sheet
//! size checked, and the sheet rasterised at a known resolution (exact box-filter coverage of
//! the axis-aligned shapes) and given to the project's detectors, which must find every
//! corner where the physical size puts it.

use std::collections::BTreeMap;

use msreg_host::camera_yaml::{AprilGridTarget, CheckerboardTarget};
use msreg_host::vision::aprilgrid::{detect_aprilgrid, AprilGridParams};
use msreg_host::vision::target_svg::{target_svg, Page, PrintTarget};
use msreg_host::vision::{detect_checkerboard, DetectorParams, GrayImage};

/// One element: its name and attributes.
struct Element {
    name: String,
    attrs: BTreeMap<String, String>,
}

/// Every start or empty-element tag of an XML document (no entities needed here).
fn elements(xml: &str) -> Vec<Element> {
    let mut out = Vec::new();
    let mut rest = xml;
    while let Some(open) = rest.find('<') {
        let close = rest[open..].find('>').expect("tag closes") + open;
        let tag = &rest[open + 1..close];
        rest = &rest[close + 1..];
        if tag.starts_with(['?', '/', '!']) {
            continue;
        }
        let tag = tag.trim_end_matches('/');
        let (name, mut attrs_text) = tag.split_once(char::is_whitespace).unwrap_or((tag, ""));
        let mut attrs = BTreeMap::new();
        while let Some(eq) = attrs_text.find('=') {
            let key = attrs_text[..eq].trim().to_string();
            let after = attrs_text[eq + 1..].trim_start();
            let quote = after.chars().next().expect("quoted value");
            let end = after[1..].find(quote).expect("value closes") + 1;
            attrs.insert(key, after[1..end].to_string());
            attrs_text = &after[end + 1..];
        }
        out.push(Element {
            name: name.to_string(),
            attrs,
        });
    }
    out
}

fn num(e: &Element, key: &str) -> f64 {
    e.attrs[key].trim_end_matches("mm").parse().expect("number")
}

/// A rectangle `[x0, y0, x1, y1]`, mm.
type Rect = [f64; 4];

/// The subpaths of a path made of `M x y H x V y H x Z` rectangles.
fn path_rects(d: &str) -> Vec<Rect> {
    d.split('M')
        .filter(|s| !s.trim().is_empty())
        .map(|s| {
            let v: Vec<f64> = s
                .split(['H', 'V', 'Z', ' '])
                .filter(|t| !t.is_empty())
                .map(|t| t.parse().expect("number"))
                .collect();
            assert_eq!(v.len(), 5, "{s}");
            assert!((v[4] - v[0]).abs() < 1e-12, "closes where it started: {s}");
            [v[0], v[1], v[2], v[3]]
        })
        .collect()
}

/// The sheet read back: size, black rectangles, tags (outline + holes).
struct Sheet {
    size: [f64; 2],
    view_box: Vec<f64>,
    rects: Vec<Rect>,
    tags: Vec<(Rect, Vec<Rect>)>,
}

fn read_sheet(svg: &str) -> Sheet {
    let els = elements(svg);
    let root = els.iter().find(|e| e.name == "svg").expect("svg element");
    assert!(root.attrs["width"].ends_with("mm") && root.attrs["height"].ends_with("mm"));
    let view_box = root.attrs["viewBox"]
        .split_whitespace()
        .map(|t| t.parse().expect("number"))
        .collect();
    let rects = els
        .iter()
        .filter(|e| e.name == "rect" && !e.attrs.contains_key("id"))
        .map(|e| {
            let (x, y) = (num(e, "x"), num(e, "y"));
            [x, y, x + num(e, "width"), y + num(e, "height")]
        })
        .collect();
    let tags = els
        .iter()
        .filter(|e| e.name == "path")
        .map(|e| {
            assert_eq!(e.attrs["fill-rule"], "evenodd");
            let mut r = path_rects(&e.attrs["d"]);
            let outline = r.remove(0);
            (outline, r)
        })
        .collect();
    Sheet {
        size: [num(root, "width"), num(root, "height")],
        view_box,
        rects,
        tags,
    }
}

/// The sheet rasterised at `px_per_mm`: white paper, black ink, each pixel the exact area
/// fraction it covers (holes of a tag subtracted from its outline).
fn rasterise(sheet: &Sheet, px_per_mm: f64) -> GrayImage {
    let (w, h) = (
        (sheet.size[0] * px_per_mm).round() as usize,
        (sheet.size[1] * px_per_mm).round() as usize,
    );
    let mut ink = vec![0.0f64; w * h];
    let mut add = |r: &Rect, sign: f64| {
        let [x0, y0, x1, y1] = r.map(|v| v * px_per_mm);
        for y in (y0.floor().max(0.0) as usize)..(y1.ceil() as usize).min(h) {
            let fy = (y1.min(y as f64 + 1.0) - y0.max(y as f64)).max(0.0);
            for x in (x0.floor().max(0.0) as usize)..(x1.ceil() as usize).min(w) {
                let fx = (x1.min(x as f64 + 1.0) - x0.max(x as f64)).max(0.0);
                ink[y * w + x] += sign * fx * fy;
            }
        }
    };
    for r in &sheet.rects {
        add(r, 1.0);
    }
    for (outline, holes) in &sheet.tags {
        add(outline, 1.0);
        for hole in holes {
            add(hole, -1.0);
        }
    }
    let data = ink
        .iter()
        .map(|&c| (255.0 * (1.0 - c.clamp(0.0, 1.0))) as f32)
        .collect();
    GrayImage::from_vec(w, h, data).expect("size")
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn checkerboard_squares_measure_the_requested_size_and_the_detector_finds_every_corner() {
    let board = CheckerboardTarget {
        rows: 6,
        cols: 8,
        row_spacing_m: 0.02,
        col_spacing_m: 0.02,
        width_m: None,
        height_m: None,
    };
    let drawn =
        target_svg(&PrintTarget::Checkerboard(board), Page::A4, 10.0).expect("fits an A4 sheet");
    let sheet = read_sheet(&drawn.svg);
    // A4 portrait; the viewBox in mm.
    assert!((sheet.size[0] - 210.0).abs() < 1e-12 && (sheet.size[1] - 297.0).abs() < 1e-12);
    assert_eq!(sheet.view_box, vec![0.0, 0.0, 210.0, 297.0]);
    // 7 x 9 squares, the black ones: 32; every one 20 mm, on a 20 mm lattice.
    assert_eq!(sheet.rects.len(), 32);
    let (x0, y0) = (
        sheet.rects.iter().map(|r| r[0]).fold(f64::MAX, f64::min),
        sheet.rects.iter().map(|r| r[1]).fold(f64::MAX, f64::min),
    );
    let mut worst: f64 = 0.0;
    for r in &sheet.rects {
        worst = worst
            .max((r[2] - r[0] - 20.0).abs())
            .max((r[3] - r[1] - 20.0).abs());
        let (i, j) = ((r[1] - y0) / 20.0, (r[0] - x0) / 20.0);
        worst = worst
            .max((i - i.round()).abs() * 20.0)
            .max((j - j.round()).abs() * 20.0);
        assert_eq!(
            (i.round() as i64 + j.round() as i64) % 2,
            0,
            "black where i + j even"
        );
    }
    println!("checkerboard: worst square size / lattice error {worst:.1e} mm");
    assert!(worst < 1e-9, "{worst}");
    // The pattern is centred across the sheet.
    assert!(close(x0 + 9.0 * 20.0 / 2.0, 105.0, 1e-9));

    let px_per_mm = 4.0;
    let image = rasterise(&sheet, px_per_mm);
    let found = detect_checkerboard(&image, 6, 8, &DetectorParams::default()).expect("board");
    let mut err: f64 = 0.0;
    for r in 0..6 {
        for c in 0..8 {
            // Corner (r, c): x down the sheet by rows, y right by columns.
            let (u, v) = (
                (x0 + 20.0 * (c + 1) as f64) * px_per_mm - 0.5,
                (y0 + 20.0 * (r + 1) as f64) * px_per_mm - 0.5,
            );
            err = err.max((found.corner(r, c) - nalgebra::Vector2::new(u, v)).norm());
        }
    }
    println!("checkerboard at {px_per_mm} px/mm: worst corner error {err:.4} px");
    assert!(err < 0.02, "{err}");
}

#[test]
fn aprilgrid_tags_and_corner_squares_measure_the_requested_size_and_every_tag_is_found() {
    let grid = AprilGridTarget {
        tag_cols: 5,
        tag_rows: 4,
        tag_size_m: 0.03,
        tag_spacing: 0.3,
    };
    let drawn = target_svg(&PrintTarget::AprilGrid(grid), Page::Auto, 10.0).expect("drawn");
    let sheet = read_sheet(&drawn.svg);
    let (s, gap) = (30.0, 9.0);
    let pitch = s + gap;
    // Auto: the pattern (5 x 39 + 9 by 4 x 39 + 9 mm), 10 mm around, 9 mm of caption.
    let (pw, ph) = (5.0 * pitch + gap, 4.0 * pitch + gap);
    assert!(close(sheet.size[0], pw + 20.0, 1e-9) && close(sheet.size[1], ph + 29.0, 1e-9));
    assert_eq!(sheet.view_box, vec![0.0, 0.0, sheet.size[0], sheet.size[1]]);
    assert_eq!(sheet.tags.len(), 20);
    assert_eq!(sheet.rects.len(), 6 * 5);
    // Tag 0's lower-left corner on the sheet: a gap in from the pattern's left and bottom.
    let left = sheet.rects.iter().map(|r| r[0]).fold(f64::MAX, f64::min);
    let bottom = sheet.rects.iter().map(|r| r[3]).fold(f64::MIN, f64::max);
    let origin = (left + gap, bottom - gap);
    let mut worst: f64 = 0.0;
    for (id, (outline, holes)) in sheet.tags.iter().enumerate() {
        let (col, row) = ((id % 5) as f64, (id / 5) as f64);
        worst = worst
            .max((outline[2] - outline[0] - s).abs())
            .max((outline[3] - outline[1] - s).abs())
            .max((outline[0] - (origin.0 + col * pitch)).abs())
            .max((outline[3] - (origin.1 - row * pitch)).abs());
        for h in holes {
            // Data cells: 3 mm, inside the 2-cell border.
            worst = worst
                .max((h[2] - h[0] - 3.0).abs())
                .max((h[3] - h[1] - 3.0).abs());
            assert!(h[0] >= outline[0] + 6.0 - 1e-9 && h[2] <= outline[2] - 6.0 + 1e-9);
            assert!(h[1] >= outline[1] + 6.0 - 1e-9 && h[3] <= outline[3] - 6.0 + 1e-9);
        }
    }
    for r in &sheet.rects {
        worst = worst
            .max((r[2] - r[0] - gap).abs())
            .max((r[3] - r[1] - gap).abs());
        let (i, j) = ((r[0] - left) / pitch, (bottom - r[3]) / pitch);
        worst = worst
            .max((i - i.round()).abs() * pitch)
            .max((j - j.round()).abs() * pitch);
    }
    println!("aprilgrid: worst tag / cell / corner-square error {worst:.1e} mm");
    assert!(worst < 1e-9, "{worst}");

    let px_per_mm = 4.0;
    let image = rasterise(&sheet, px_per_mm);
    let found = detect_aprilgrid(&image, &grid, &AprilGridParams::default()).expect("grid");
    assert_eq!(
        found.ids,
        (0..80).collect::<Vec<_>>(),
        "every corner of every tag"
    );
    let mut err: f64 = 0.0;
    for (&id, px) in found.ids.iter().zip(&found.pixels) {
        let p = grid.corner(id).expect("id on the grid") * 1e3;
        let (u, v) = (
            (origin.0 + p.x) * px_per_mm - 0.5,
            (origin.1 - p.y) * px_per_mm - 0.5,
        );
        err = err.max((px - nalgebra::Vector2::new(u, v)).norm());
    }
    println!("aprilgrid at {px_per_mm} px/mm: worst corner error {err:.4} px");
    assert!(err < 0.05, "{err}");
}

#[test]
fn pages_that_are_too_small_and_bad_sizes_are_refused() {
    let big = CheckerboardTarget {
        rows: 8,
        cols: 11,
        row_spacing_m: 0.03,
        col_spacing_m: 0.03,
        width_m: None,
        height_m: None,
    };
    // 360 x 270 mm of squares: not on A4 either way; on A3 landscape with a 5 mm border
    // (289 mm high with the caption), not with 10 mm (299 mm).
    assert!(target_svg(&PrintTarget::Checkerboard(big), Page::A4, 10.0).is_err());
    assert!(target_svg(&PrintTarget::Checkerboard(big), Page::A3, 10.0).is_err());
    let a3 = target_svg(&PrintTarget::Checkerboard(big), Page::A3, 5.0).expect("A3");
    assert!((a3.width_mm - 420.0).abs() < 1e-12 && (a3.height_mm - 297.0).abs() < 1e-12);
    let tiny = CheckerboardTarget { rows: 2, ..big };
    assert!(target_svg(&PrintTarget::Checkerboard(tiny), Page::Auto, 10.0).is_err());
    assert!(target_svg(&PrintTarget::Checkerboard(big), Page::Auto, f64::NAN).is_err());
}
