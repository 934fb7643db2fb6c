//! Target sizes that read as millimetres. (The IMU's units are checked by the dataset
//! loader, [`crate::dataset::check_imu_units`], whose message the check passes on.)

use std::path::Path;

use super::Finding;
use crate::camera_yaml::Target;

/// Largest plausible square or tag side, m: a printed corner target with 0.5 m squares
/// does not exist, while 60 (mm) written as metres is a 60 m square.
pub const MAX_SQUARE_M: f64 = 0.5;
/// Largest plausible physical board side, m.
pub const MAX_BOARD_M: f64 = 20.0;

/// Each size of `target` at `path` too large to be metres.
pub fn target_in_millimetres(path: &Path, target: &Target) -> Vec<Finding> {
    let sizes: Vec<(&'static str, Option<f64>, f64)> = match target {
        Target::Checkerboard(t) => vec![
            ("rowSpacingMeters", Some(t.row_spacing_m), MAX_SQUARE_M),
            ("colSpacingMeters", Some(t.col_spacing_m), MAX_SQUARE_M),
            ("width_m", t.width_m, MAX_BOARD_M),
            ("height_m", t.height_m, MAX_BOARD_M),
        ],
        Target::AprilGrid(t) => vec![("tagSize", Some(t.tag_size_m), MAX_SQUARE_M)],
        Target::Board(b) => vec![
            ("width_m", Some(b.width_m), MAX_BOARD_M),
            ("height_m", Some(b.height_m), MAX_BOARD_M),
        ],
    };
    let text = std::fs::read_to_string(path).unwrap_or_default();
    sizes
        .into_iter()
        .filter_map(|(key, value, max)| Some((key, value?, max)))
        .filter(|(_, value, max)| value > max)
        .map(|(key, value, _)| Finding::TargetInMillimetres {
            path: path.to_path_buf(),
            line: super::keys::line_of(&text, key),
            key,
            value,
        })
        .collect()
}
