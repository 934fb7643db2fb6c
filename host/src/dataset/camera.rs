//! The camera parts of the dataset layout: `cam0/data.csv` (EuRoC: timestamp, file name of
//! an image in `cam0/data/`), `groundtruth/corners.csv` (true pixel of every board corner per
//! frame) and `groundtruth/target_poses.csv` (pose of the target in `G`, the `pose0/data.csv`
//! format). `cam0/camera.yaml` and `target.yaml` are read by [`crate::camera_yaml`].

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::Vector2;

use super::csv::{fmt_f64, io_error, parse_row, read_text};
use super::error::DatasetError;
use super::pose::{read_pose_csv, PoseRecord};

/// Image list (EuRoC).
pub const CAMERA_CSV: &str = "cam0/data.csv";
/// Directory of the images named in [`CAMERA_CSV`].
pub const CAMERA_DATA_DIR: &str = "cam0/data";
/// Kalibr camera description.
pub const CAMERA_YAML: &str = "cam0/camera.yaml";
/// Kalibr target description.
pub const TARGET_YAML: &str = "target.yaml";
/// True corner pixels (simulator output).
pub const GROUNDTRUTH_CORNERS_CSV: &str = "groundtruth/corners.csv";
/// True target poses `T_G_T` (simulator output).
pub const GROUNDTRUTH_TARGET_POSES_CSV: &str = "groundtruth/target_poses.csv";

/// One image of `cam0/data.csv`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraFrame {
    /// Image stamp, camera clock, ns.
    pub stamp_ns: u64,
    /// The image file (`cam0/data/<filename>` resolved against the dataset).
    pub path: PathBuf,
}

const CAMERA_HEADER: &str = "#timestamp [ns],filename";

/// Reads `cam0/data.csv` (`timestamp [ns], filename`); file names are resolved against the
/// `data/` directory beside the CSV. Rejects a missing or empty file, a line without two
/// columns, a non-integer stamp, an empty file name and stamps that do not strictly increase,
/// naming the file and line. The images themselves are not opened.
pub fn read_camera_csv(path: impl AsRef<Path>) -> Result<Vec<CameraFrame>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path)?;
    let data_dir = path.parent().unwrap_or(Path::new(".")).join("data");
    let mut frames: Vec<CameraFrame> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let malformed = |expected: String| DatasetError::MalformedLine {
            path: path.to_path_buf(),
            line,
            expected,
        };
        let fields: Vec<&str> = trimmed.split(',').map(str::trim).collect();
        if fields.len() != 2 || fields[1].is_empty() {
            return Err(malformed(format!(
                "2 comma-separated columns (timestamp [ns], filename), found `{trimmed}`"
            )));
        }
        let stamp_ns = fields[0].parse::<u64>().map_err(|_| {
            malformed(format!(
                "an integer timestamp in nanoseconds in column 1, found `{}`",
                fields[0]
            ))
        })?;
        if let Some(previous) = frames.last() {
            if stamp_ns <= previous.stamp_ns {
                return Err(DatasetError::TimeNotIncreasing {
                    path: path.to_path_buf(),
                    line,
                    stamp_ns,
                    previous_ns: previous.stamp_ns,
                });
            }
        }
        frames.push(CameraFrame {
            stamp_ns,
            path: data_dir.join(fields[1]),
        });
    }
    if frames.is_empty() {
        return Err(DatasetError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(frames)
}

/// Writes `cam0/data.csv`: the file name of each frame's path.
pub fn write_camera_csv(
    path: impl AsRef<Path>,
    frames: &[CameraFrame],
) -> Result<(), DatasetError> {
    let path = path.as_ref();
    let file = File::create(path).map_err(|source| io_error(path, source))?;
    let mut out = BufWriter::new(file);
    let mut write = || -> std::io::Result<()> {
        writeln!(out, "{CAMERA_HEADER}")?;
        for f in frames {
            let name = f.path.file_name().map(|n| n.to_string_lossy().into_owned());
            writeln!(out, "{},{}", f.stamp_ns, name.unwrap_or_default())?;
        }
        out.flush()
    };
    write().map_err(|source| io_error(path, source))
}

/// One row of `groundtruth/corners.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerTruth {
    /// Image stamp, camera clock, ns.
    pub stamp_ns: u64,
    /// Kalibr corner id `r * cols + c`.
    pub corner_id: usize,
    /// True pixel (centre of the top-left pixel = (0, 0)).
    pub pixel: Vector2<f64>,
    /// Whether the pixel lies on the image.
    pub in_image: bool,
}

const CORNER_COLUMNS: &str = "timestamp [ns], corner_id, u, v, in_image (0 or 1)";
const CORNER_HEADER: &str = "#timestamp [ns],corner_id,u [px],v [px],in_image";

/// Reads `groundtruth/corners.csv`. Several rows share a stamp; stamps must not decrease,
/// ids must be non-negative integers and `in_image` 0 or 1.
pub fn read_corners_csv(path: impl AsRef<Path>) -> Result<Vec<CornerTruth>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path)?;
    let mut out: Vec<CornerTruth> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let row = parse_row::<4>(path, line, trimmed, CORNER_COLUMNS)?;
        let [id, u, v, flag] = row.values;
        let malformed = |expected: &str| DatasetError::MalformedLine {
            path: path.to_path_buf(),
            line,
            expected: expected.to_string(),
        };
        if id < 0.0 || id.fract() != 0.0 || id > 1e9 {
            return Err(malformed("a non-negative integer corner_id in column 2"));
        }
        let in_image = match flag {
            f if f == 0.0 => false,
            f if f == 1.0 => true,
            _ => return Err(malformed("in_image 0 or 1 in column 5")),
        };
        if let Some(previous) = out.last() {
            if row.stamp_ns < previous.stamp_ns {
                return Err(DatasetError::TimeNotIncreasing {
                    path: path.to_path_buf(),
                    line,
                    stamp_ns: row.stamp_ns,
                    previous_ns: previous.stamp_ns,
                });
            }
        }
        out.push(CornerTruth {
            stamp_ns: row.stamp_ns,
            corner_id: id as usize,
            pixel: Vector2::new(u, v),
            in_image,
        });
    }
    if out.is_empty() {
        return Err(DatasetError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(out)
}

/// Writes `groundtruth/corners.csv` (rows in the given order, stamps non-decreasing).
pub fn write_corners_csv(path: impl AsRef<Path>, rows: &[CornerTruth]) -> Result<(), DatasetError> {
    let path = path.as_ref();
    let file = File::create(path).map_err(|source| io_error(path, source))?;
    let mut out = BufWriter::new(file);
    let mut write = || -> std::io::Result<()> {
        writeln!(out, "{CORNER_HEADER}")?;
        for r in rows {
            writeln!(
                out,
                "{},{},{},{},{}",
                r.stamp_ns,
                r.corner_id,
                fmt_f64(r.pixel.x),
                fmt_f64(r.pixel.y),
                u8::from(r.in_image)
            )?;
        }
        out.flush()
    };
    write().map_err(|source| io_error(path, source))
}

/// Reads `groundtruth/target_poses.csv`: `timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z`, the
/// pose `T_G_T` of the target in `G` (the `pose0/data.csv` format and checks).
pub fn read_target_poses_csv(path: impl AsRef<Path>) -> Result<Vec<PoseRecord>, DatasetError> {
    read_pose_csv(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    #[test]
    fn camera_csv_round_trips_and_resolves_names() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("data.csv");
        let frames = vec![
            CameraFrame {
                stamp_ns: 10,
                path: dir.path().join("data").join("10.png"),
            },
            CameraFrame {
                stamp_ns: 20,
                path: dir.path().join("data").join("20.png"),
            },
        ];
        write_camera_csv(&path, &frames)?;
        assert_eq!(read_camera_csv(&path)?, frames);
        // EuRoC's own header and spaces.
        std::fs::write(&path, "#timestamp [ns],filename\r\n5 , a.png\n")?;
        assert_eq!(
            read_camera_csv(&path)?[0].path,
            dir.path().join("data/a.png")
        );
        Ok(())
    }

    #[test]
    fn camera_csv_errors_name_file_and_line() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("data.csv");
        let err = read_camera_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::MissingFile { .. }));
        for (text, line) in [
            ("#h\n1,a.png\n2\n", 3),
            ("1,a.png,extra\n", 1),
            ("1.5,a.png\n", 1),
            ("1,\n", 1),
        ] {
            std::fs::write(&path, text)?;
            let err = read_camera_csv(&path).err().ok_or("expected an error")?;
            assert!(
                matches!(err, DatasetError::MalformedLine { line: l, .. } if l == line),
                "{text:?}: {err}"
            );
            assert!(
                err.to_string().contains(&format!("data.csv:{line}")),
                "{err}"
            );
        }
        std::fs::write(&path, "2,a.png\n2,b.png\n")?;
        let err = read_camera_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(
            err,
            DatasetError::TimeNotIncreasing { line: 2, .. }
        ));
        std::fs::write(&path, "#only a header\n")?;
        let err = read_camera_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::Empty { .. }));
        Ok(())
    }

    #[test]
    fn corners_csv_round_trips_and_checks_values() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("corners.csv");
        let rows = vec![
            CornerTruth {
                stamp_ns: 7,
                corner_id: 0,
                pixel: Vector2::new(100.25, 3.0e-7),
                in_image: true,
            },
            CornerTruth {
                stamp_ns: 7,
                corner_id: 41,
                pixel: Vector2::new(-3.5, 480.125),
                in_image: false,
            },
            CornerTruth {
                stamp_ns: 9,
                corner_id: 1,
                pixel: Vector2::new(1.0 / 3.0, 2.0),
                in_image: true,
            },
        ];
        write_corners_csv(&path, &rows)?;
        assert_eq!(read_corners_csv(&path)?, rows);
        for (text, what) in [
            ("1,0.5,1,2,1\n", "corner_id"),
            ("1,-1,1,2,1\n", "corner_id"),
            ("1,3,1,2,2\n", "in_image"),
            ("1,3,1,2\n", "columns"),
            ("1,3,nan,2,1\n", "finite"),
        ] {
            std::fs::write(&path, text)?;
            let err = read_corners_csv(&path).err().ok_or("expected an error")?;
            assert!(err.to_string().contains("corners.csv:1"), "{err}");
            assert!(err.to_string().contains(what), "{what}: {err}");
        }
        std::fs::write(&path, "5,0,1,1,1\n4,0,1,1,1\n")?;
        let err = read_corners_csv(&path).err().ok_or("expected an error")?;
        assert!(matches!(
            err,
            DatasetError::TimeNotIncreasing { line: 2, .. }
        ));
        Ok(())
    }
}
