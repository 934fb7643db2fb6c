//! `cam0/corners.csv`: target corners detected beforehand by any tool (Kalibr, OpenCV,
//! an AprilGrid detector), read instead of images. Rows are `timestamp [ns], corner_id, u, v`
//! with an optional `x, y, z` (the corner in the target frame, metres); rows of one image
//! share their stamp, stamps never decrease. Without `x, y, z` the target of `target.yaml`
//! places the corner by its id.

use std::path::Path;

use nalgebra::{Vector2, Vector3};

use super::csv::{parse_row, read_text};
use super::error::DatasetError;

/// `cam0/corners.csv` under a dataset root.
pub const OBSERVED_CORNERS_CSV: &str = "cam0/corners.csv";

const COLUMNS: &str = "timestamp [ns], corner_id, u, v[, x, y, z]";

/// One detected corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservedCorner {
    /// Target corner id (its meaning is the target's: Kalibr ids for checkerboard and
    /// AprilGrid).
    pub corner_id: usize,
    /// Pixel (OpenCV convention: the centre of the top-left pixel is (0, 0)).
    pub pixel: Vector2<f64>,
    /// Position in the target frame, m, when the file gives it.
    pub point: Option<Vector3<f64>>,
}

/// The corners detected in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservedImage {
    /// Image stamp, camera clock, ns.
    pub stamp_ns: u64,
    /// Its corners, in file order.
    pub corners: Vec<ObservedCorner>,
}

/// Reads `cam0/corners.csv` (4 or 7 columns, the same for every row), grouped by stamp.
pub fn read_observed_corners(path: impl AsRef<Path>) -> Result<Vec<ObservedImage>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path)?;
    let mut images: Vec<ObservedImage> = Vec::new();
    let mut width = None;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let columns = trimmed.split(',').count();
        let malformed = |expected: &str| DatasetError::MalformedLine {
            path: path.to_path_buf(),
            line,
            expected: expected.to_string(),
        };
        if *width.get_or_insert(columns) != columns {
            return Err(malformed(
                "the same number of columns on every row (4, or 7 with x, y, z)",
            ));
        }
        let (stamp_ns, corner) = if columns == 7 {
            let row = parse_row::<6>(path, line, trimmed, COLUMNS)?;
            let [id, u, v, x, y, z] = row.values;
            (row.stamp_ns, corner(id, u, v, Some(Vector3::new(x, y, z))))
        } else {
            let row = parse_row::<3>(path, line, trimmed, COLUMNS)?;
            let [id, u, v] = row.values;
            (row.stamp_ns, corner(id, u, v, None))
        };
        let corner =
            corner.ok_or_else(|| malformed("a non-negative integer corner_id in column 2"))?;
        match images.last_mut() {
            Some(last) if last.stamp_ns == stamp_ns => last.corners.push(corner),
            Some(last) if stamp_ns < last.stamp_ns => {
                return Err(DatasetError::TimeNotIncreasing {
                    path: path.to_path_buf(),
                    line,
                    stamp_ns,
                    previous_ns: last.stamp_ns,
                })
            }
            _ => images.push(ObservedImage {
                stamp_ns,
                corners: vec![corner],
            }),
        }
    }
    if images.is_empty() {
        return Err(DatasetError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(images)
}

fn corner(id: f64, u: f64, v: f64, point: Option<Vector3<f64>>) -> Option<ObservedCorner> {
    (id >= 0.0 && id.fract() == 0.0 && id <= 1e9).then(|| ObservedCorner {
        corner_id: id as usize,
        pixel: Vector2::new(u, v),
        point,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<Vec<ObservedImage>, DatasetError> {
        let dir = tempfile::tempdir().map_err(|e| DatasetError::Io {
            path: "tempdir".into(),
            source: e,
        })?;
        let path = dir.path().join("corners.csv");
        std::fs::write(&path, text).map_err(|e| DatasetError::Io {
            path: path.clone(),
            source: e,
        })?;
        read_observed_corners(&path)
    }

    #[test]
    fn rows_group_by_stamp_with_and_without_points() -> Result<(), DatasetError> {
        let with = read("#t,id,u,v,x,y,z\n10,0,1.5,2.5,0,0,0\n10,1,3,4,0.1,0,0\n20,0,5,6,0,0,0\n")?;
        assert_eq!(with.len(), 2);
        assert_eq!(with[0].corners.len(), 2);
        assert_eq!(with[0].corners[1].point, Some(Vector3::new(0.1, 0.0, 0.0)));
        let without = read("10,3,1,2\n20,4,3,4\n")?;
        assert_eq!(without[1].corners[0].corner_id, 4);
        assert_eq!(without[1].corners[0].point, None);
        Ok(())
    }

    #[test]
    fn bad_rows_name_the_line() {
        let mixed = read("10,0,1,2\n10,1,1,2,0,0,0\n");
        assert!(matches!(
            mixed,
            Err(DatasetError::MalformedLine { line: 2, .. })
        ));
        let backwards = read("20,0,1,2\n10,0,1,2\n");
        assert!(matches!(
            backwards,
            Err(DatasetError::TimeNotIncreasing { line: 2, .. })
        ));
        let negative_id = read("10,-1,1,2\n");
        assert!(matches!(
            negative_id,
            Err(DatasetError::MalformedLine { line: 1, .. })
        ));
    }
}
