//! Decoding of the PCD data section into a [`PointCloud`].

use std::path::Path;

use nalgebra::Vector3;

use super::header::{parse_header, PcdDataEncoding, PcdHeader, PcdScalarType};
use super::{lzf, PcdError, Point, PointCloud};

/// The fields this reader extracts, in [`Slot`] order.
const WANTED: [&str; 6] = ["x", "y", "z", "intensity", "t", "ring"];

/// Where one wanted field lives: scalar type plus byte offset within a record
/// (binary), within the decompressed block (compressed, start of its column),
/// or token index (ascii).
#[derive(Clone, Copy)]
struct Slot {
    scalar: PcdScalarType,
    offset: usize,
}

/// Reads a PCD file (ascii, binary or binary_compressed).
pub fn read_pcd(path: impl AsRef<Path>) -> Result<PointCloud, PcdError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| PcdError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_pcd(path, &bytes)
}

/// Parses PCD bytes; `path` only names the source in errors.
pub fn parse_pcd(path: &Path, bytes: &[u8]) -> Result<PointCloud, PcdError> {
    let (header, data_start) = parse_header(path, bytes)?;
    let data = &bytes[data_start..];
    let total = header.points;
    let points = match header.encoding {
        PcdDataEncoding::Ascii => decode_ascii(path, &header, data)?,
        PcdDataEncoding::Binary => decode_binary(path, &header, data)?,
        PcdDataEncoding::BinaryCompressed => decode_compressed(path, &header, data)?,
    };
    if points.is_empty() {
        let detail = if total == 0 {
            String::new()
        } else {
            format!(" with finite coordinates ({total} non-finite points dropped)")
        };
        return Err(PcdError::ZeroPoints {
            path: path.to_path_buf(),
            detail,
        });
    }
    Ok(PointCloud::new(points))
}

/// One slot per wanted field, `None` when the file lacks it; `offset_of`
/// gives a field's position given its index.
fn slots(header: &PcdHeader, offset_of: impl Fn(usize) -> usize) -> [Option<Slot>; 6] {
    WANTED.map(|name| {
        header.field_index(name).map(|i| Slot {
            scalar: header.fields[i].scalar,
            offset: offset_of(i),
        })
    })
}

/// Builds a point from the six wanted values (missing ones are 0); `None`
/// when a coordinate is not finite.
fn make_point(v: [f64; 6]) -> Option<Point> {
    let xyz = Vector3::new(v[0], v[1], v[2]);
    if !xyz.iter().all(|c| c.is_finite()) {
        return None;
    }
    let to_u = |x: f64, max: f64| {
        if x.is_finite() {
            x.round().clamp(0.0, max)
        } else {
            0.0
        }
    };
    Some(Point {
        xyz,
        intensity: v[3] as f32,
        t_ns: to_u(v[4], f64::from(u32::MAX)) as u32,
        ring: to_u(v[5], f64::from(u16::MAX)) as u16,
    })
}

fn decode_binary(path: &Path, header: &PcdHeader, data: &[u8]) -> Result<Vec<Point>, PcdError> {
    let record = header.point_size();
    let expected = record * header.points;
    if data.len() < expected {
        return Err(PcdError::Truncated {
            path: path.to_path_buf(),
            expected,
            actual: data.len(),
            unit: "bytes",
        });
    }
    let slots = slots(header, |i| {
        header.fields[..i]
            .iter()
            .map(|f| f.scalar.size() * f.count)
            .sum()
    });
    let points = data[..expected]
        .chunks_exact(record)
        .filter_map(|rec| {
            make_point(slots.map(|s| s.map_or(0.0, |s| s.scalar.decode_le(&rec[s.offset..]))))
        })
        .collect();
    Ok(points)
}

fn decode_compressed(path: &Path, header: &PcdHeader, data: &[u8]) -> Result<Vec<Point>, PcdError> {
    let word = |at: usize| -> Result<usize, PcdError> {
        let b = data.get(at..at + 4).ok_or_else(|| PcdError::Truncated {
            path: path.to_path_buf(),
            expected: 8,
            actual: data.len(),
            unit: "bytes of compressed-size header",
        })?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let compressed_len = word(0)?;
    let raw_len = word(4)?;
    let expected = header.point_size() * header.points;
    if raw_len != expected {
        return Err(PcdError::Compressed {
            path: path.to_path_buf(),
            message: format!(
                "uncompressed size {raw_len} differs from POINTS * point size = {expected}"
            ),
        });
    }
    let body = data
        .get(8..8 + compressed_len)
        .ok_or_else(|| PcdError::Truncated {
            path: path.to_path_buf(),
            expected: compressed_len,
            actual: data.len().saturating_sub(8),
            unit: "compressed bytes",
        })?;
    let raw = lzf::decompress(body, raw_len).map_err(|message| PcdError::Compressed {
        path: path.to_path_buf(),
        message,
    })?;
    let n = header.points;
    let slots = slots(header, |i| {
        header.fields[..i]
            .iter()
            .map(|f| f.scalar.size() * f.count * n)
            .sum()
    });
    let points = (0..n)
        .filter_map(|k| {
            make_point(slots.map(|s| {
                // Column-major: each element of a COUNT>1 field is its own run
                // of `n` values; the first element's run starts the column.
                s.map_or(0.0, |s| {
                    s.scalar.decode_le(&raw[s.offset + k * s.scalar.size()..])
                })
            }))
        })
        .collect();
    Ok(points)
}

fn decode_ascii(path: &Path, header: &PcdHeader, data: &[u8]) -> Result<Vec<Point>, PcdError> {
    let text = String::from_utf8_lossy(data);
    let tokens_per_point: usize = header.fields.iter().map(|f| f.count).sum();
    let slots = slots(header, |i| header.fields[..i].iter().map(|f| f.count).sum());
    let mut points = Vec::with_capacity(header.points);
    let mut seen = 0usize;
    for (k, line) in text.lines().enumerate() {
        if seen == header.points {
            break;
        }
        let line_no = header.data_line + 1 + k;
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.is_empty() {
            continue;
        }
        if tokens.len() != tokens_per_point {
            return Err(PcdError::AsciiData {
                path: path.to_path_buf(),
                line: line_no,
                message: format!(
                    "{} values, header declares {tokens_per_point}",
                    tokens.len()
                ),
            });
        }
        let mut values = [0.0; 6];
        for (value, slot) in values.iter_mut().zip(slots) {
            if let Some(s) = slot {
                let token = tokens[s.offset];
                *value = token.parse::<f64>().map_err(|_| PcdError::AsciiData {
                    path: path.to_path_buf(),
                    line: line_no,
                    message: format!("`{token}` is not a number"),
                })?;
            }
        }
        seen += 1;
        points.extend(make_point(values));
    }
    if seen < header.points {
        return Err(PcdError::Truncated {
            path: path.to_path_buf(),
            expected: header.points,
            actual: seen,
            unit: "points (ascii lines)",
        });
    }
    Ok(points)
}
