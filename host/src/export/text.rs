//! Number and matrix text shared by the formats: shortest exact floats that YAML 1.1,
//! YAML 1.2, OpenCV's FileStorage and XML attributes all read back to the same f64.

use nalgebra::{Isometry3, Matrix4};

/// `x` in its shortest exact form, always with a `.` before any exponent (`1.0e-5`), so
/// YAML 1.1 readers see a float.
pub(super) fn float(x: f64) -> String {
    let s = format!("{x:?}");
    match s.find('e') {
        Some(at) if !s[..at].contains('.') => format!("{}.0{}", &s[..at], &s[at..]),
        _ => s,
    }
}

/// `[a, b, c]`.
pub(super) fn flow(values: impl IntoIterator<Item = f64>) -> String {
    let items: Vec<String> = values.into_iter().map(float).collect();
    format!("[{}]", items.join(", "))
}

/// The 4x4 matrix as four YAML block rows, each `indent- [a, b, c, d]`.
pub(super) fn block_rows(t: &Isometry3<f64>, indent: &str) -> String {
    let m: Matrix4<f64> = t.to_homogeneous();
    (0..4)
        .map(|r| format!("{indent}- {}\n", flow((0..4).map(|c| m[(r, c)]))))
        .collect()
}

/// The 16 entries row-major.
pub(super) fn row_major(t: &Isometry3<f64>) -> Vec<f64> {
    let m: Matrix4<f64> = t.to_homogeneous();
    (0..16).map(|i| m[(i / 4, i % 4)]).collect()
}

/// `[x, y, z, w]` of the rotation, `w >= 0`.
pub(super) fn quaternion_xyzw(t: &Isometry3<f64>) -> [f64; 4] {
    let q = t.rotation.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.i, s * q.j, s * q.k, s * q.w]
}
