//! The file writers every simulator shares: directories, text files, 8-bit PNGs and PCD
//! scans, each failing with [`DatasetError::Io`] naming the file.

use std::path::Path;

use crate::dataset::DatasetError;
use crate::pointcloud::{write_pcd, PcdWriteOptions, PointCloud};
use crate::vision::GrayImage;

fn io_error(path: &Path, source: std::io::Error) -> DatasetError {
    DatasetError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Creates `dir/<sub>` (and its parents) for every `sub`.
pub fn create_dirs(dir: &Path, subs: &[&str]) -> Result<(), DatasetError> {
    subs.iter().try_for_each(|sub| {
        let path = dir.join(sub);
        std::fs::create_dir_all(&path).map_err(|source| io_error(&path, source))
    })
}

/// Writes `text` to `path`.
pub fn write_text(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(|source| io_error(path, source))
}

/// An 8-bit grey PNG with fast compression (rendering, not zlib, should dominate).
pub fn write_png(path: &Path, img: &GrayImage) -> Result<(), DatasetError> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    let io = |source: std::io::Error| io_error(path, source);
    let luma = img.to_luma8();
    let file = std::fs::File::create(path).map_err(io)?;
    let encoder = PngEncoder::new_with_quality(
        std::io::BufWriter::new(file),
        CompressionType::Fast,
        FilterType::Sub,
    );
    encoder
        .write_image(
            luma.as_raw(),
            luma.width(),
            luma.height(),
            image::ExtendedColorType::L8,
        )
        .map_err(|e| io(std::io::Error::other(e.to_string())))
}

/// A scan as a binary PCD file.
pub fn write_scan(path: &Path, cloud: &PointCloud) -> Result<(), DatasetError> {
    write_pcd(path, cloud, PcdWriteOptions::default())
        .map_err(|e| io_error(path, std::io::Error::other(e.to_string())))
}
