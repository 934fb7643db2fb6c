//! PCD writer: fields `x y z intensity t ring` (`F4|F8 F4 U4 U2`), ascii or
//! binary, `HEIGHT 1`.

use std::fmt::Write as _;
use std::path::Path;

use super::{PcdError, PointCloud};

/// Data encoding written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PcdEncoding {
    /// Text, shortest round-trip decimal of each value.
    Ascii,
    /// Little-endian records.
    #[default]
    Binary,
}

/// Options of [`write_pcd`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PcdWriteOptions {
    /// Data encoding.
    pub encoding: PcdEncoding,
    /// Write `x y z` as `F8` (exact `f64`) instead of the customary `F4`
    /// (rounded to `f32`: 8 um at 100 m).
    pub xyz_f64: bool,
}

/// Serialises `cloud` to PCD bytes.
pub fn encode_pcd(cloud: &PointCloud, options: PcdWriteOptions) -> Vec<u8> {
    let n = cloud.points.len();
    let xyz_size = if options.xyz_f64 { 8 } else { 4 };
    let data = match options.encoding {
        PcdEncoding::Ascii => "ascii",
        PcdEncoding::Binary => "binary",
    };
    let header = format!(
        "# .PCD v0.7 - Point Cloud Data file format (msreg)\nVERSION 0.7\n\
         FIELDS x y z intensity t ring\nSIZE {xyz_size} {xyz_size} {xyz_size} 4 4 2\n\
         TYPE F F F F U U\nCOUNT 1 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
         VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    );
    let mut out = header.into_bytes();
    match options.encoding {
        PcdEncoding::Ascii => {
            let mut text = String::with_capacity(n * 48);
            for p in &cloud.points {
                let [x, y, z] = [p.xyz.x, p.xyz.y, p.xyz.z];
                // `{}` prints the shortest decimal that reads back bit-exact.
                let _ = if options.xyz_f64 {
                    writeln!(text, "{x} {y} {z} {} {} {}", p.intensity, p.t_ns, p.ring)
                } else {
                    writeln!(
                        text,
                        "{} {} {} {} {} {}",
                        x as f32, y as f32, z as f32, p.intensity, p.t_ns, p.ring
                    )
                };
            }
            out.extend_from_slice(text.as_bytes());
        }
        PcdEncoding::Binary => {
            out.reserve(n * (3 * xyz_size + 10));
            for p in &cloud.points {
                for c in [p.xyz.x, p.xyz.y, p.xyz.z] {
                    if options.xyz_f64 {
                        out.extend_from_slice(&c.to_le_bytes());
                    } else {
                        out.extend_from_slice(&(c as f32).to_le_bytes());
                    }
                }
                out.extend_from_slice(&p.intensity.to_le_bytes());
                out.extend_from_slice(&p.t_ns.to_le_bytes());
                out.extend_from_slice(&p.ring.to_le_bytes());
            }
        }
    }
    out
}

/// Writes `cloud` to `path` as PCD.
pub fn write_pcd(
    path: impl AsRef<Path>,
    cloud: &PointCloud,
    options: PcdWriteOptions,
) -> Result<(), PcdError> {
    let path = path.as_ref();
    std::fs::write(path, encode_pcd(cloud, options)).map_err(|source| PcdError::Io {
        path: path.to_path_buf(),
        source,
    })
}
