//! `sensor_msgs/Image` and `sensor_msgs/CompressedImage` to the PNG files of `cam0/data/`.
//! Raw images keep their pixels (mono8/16 as grey, colour as RGB(A)); JPEG payloads are
//! decoded and stored as PNG (lossless from the decoded pixels), PNG payloads as they are.

use image::{DynamicImage, GrayImage, ImageBuffer, ImageFormat, Luma, RgbImage, RgbaImage};

use super::error::DecodeError;
use super::msgs::{CompressedImageMsg, ImageMsg};

/// What to write for one image message.
#[derive(Debug)]
pub enum ImageOut {
    /// Encode these pixels as PNG.
    Pixels(DynamicImage),
    /// The payload already is a PNG file.
    PngBytes(Vec<u8>),
}

/// Rows of `bytes_per_row` bytes, `step` apart, as one packed buffer.
fn packed(msg: &ImageMsg<'_>, bytes_per_row: usize) -> Result<Vec<u8>, DecodeError> {
    let (h, step) = (msg.height as usize, msg.step as usize);
    let need = if h == 0 {
        0
    } else {
        (h - 1) * step + bytes_per_row
    };
    if msg.data.len() < need || step < bytes_per_row {
        return Err(DecodeError::DataSize {
            len: msg.data.len(),
            need,
        });
    }
    let mut out = Vec::with_capacity(h * bytes_per_row);
    for row in 0..h {
        out.extend_from_slice(&msg.data[row * step..row * step + bytes_per_row]);
    }
    Ok(out)
}

fn size_error(msg: &ImageMsg<'_>) -> DecodeError {
    DecodeError::DataSize {
        len: msg.data.len(),
        need: msg.height as usize * msg.step as usize,
    }
}

/// Converts a raw image.
pub fn convert_image(msg: &ImageMsg<'_>) -> Result<ImageOut, DecodeError> {
    let (w, h) = (msg.width, msg.height);
    let wu = w as usize;
    let image = match msg.encoding.as_str() {
        "mono8" | "8UC1" => DynamicImage::ImageLuma8(
            GrayImage::from_raw(w, h, packed(msg, wu)?).ok_or_else(|| size_error(msg))?,
        ),
        "mono16" | "16UC1" => {
            let bytes = packed(msg, 2 * wu)?;
            let px = bytes
                .chunks_exact(2)
                .map(|c| {
                    if msg.is_bigendian {
                        u16::from_be_bytes([c[0], c[1]])
                    } else {
                        u16::from_le_bytes([c[0], c[1]])
                    }
                })
                .collect();
            let buffer: ImageBuffer<Luma<u16>, Vec<u16>> =
                ImageBuffer::from_raw(w, h, px).ok_or_else(|| size_error(msg))?;
            DynamicImage::ImageLuma16(buffer)
        }
        "rgb8" | "bgr8" | "8UC3" => {
            let mut px = packed(msg, 3 * wu)?;
            if msg.encoding != "rgb8" {
                px.chunks_exact_mut(3).for_each(|c| c.swap(0, 2));
            }
            DynamicImage::ImageRgb8(RgbImage::from_raw(w, h, px).ok_or_else(|| size_error(msg))?)
        }
        "rgba8" | "bgra8" => {
            let mut px = packed(msg, 4 * wu)?;
            if msg.encoding == "bgra8" {
                px.chunks_exact_mut(4).for_each(|c| c.swap(0, 2));
            }
            DynamicImage::ImageRgba8(RgbaImage::from_raw(w, h, px).ok_or_else(|| size_error(msg))?)
        }
        other => {
            return Err(DecodeError::ImageEncoding {
                encoding: other.to_string(),
            })
        }
    };
    Ok(ImageOut::Pixels(image))
}

/// Converts a compressed image (`jpeg` / `png`, as image_transport names them).
pub fn convert_compressed(msg: &CompressedImageMsg<'_>) -> Result<ImageOut, DecodeError> {
    let format = msg.format.to_ascii_lowercase();
    let unsupported = || DecodeError::CompressedFormat {
        format: msg.format.clone(),
    };
    if format.contains("compresseddepth") {
        return Err(unsupported());
    }
    let kind = if format.contains("png") {
        ImageFormat::Png
    } else if format.contains("jpeg") || format.contains("jpg") {
        ImageFormat::Jpeg
    } else {
        return Err(unsupported());
    };
    if kind == ImageFormat::Png {
        return Ok(ImageOut::PngBytes(msg.data.to_vec()));
    }
    image::load_from_memory_with_format(msg.data, kind)
        .map(ImageOut::Pixels)
        .map_err(|source| DecodeError::ImagePayload { source })
}
