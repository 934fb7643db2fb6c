//! A single-channel `f32` image (grey levels 0..255) with the few operations the detector
//! needs: loading PNG/JPEG (colour converted to luma), bilinear sampling with the pixel
//! convention of docs/formats.md (centre of the top-left pixel = (0, 0)), separable Gaussian
//! blur and box means.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

/// Why an image could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ImageLoadError {
    /// The file could not be opened or read.
    #[error("{path}: cannot read image")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not a decodable PNG/JPEG.
    #[error("{path}: cannot decode image")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: image::ImageError,
    },
    /// Zero width or height.
    #[error("{path}: empty image")]
    Empty {
        /// The file.
        path: PathBuf,
    },
}

/// A grey image, row-major, values in 0..255 (not clamped after filtering).
#[derive(Clone, Debug, PartialEq)]
pub struct GrayImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl GrayImage {
    /// A constant image.
    pub fn new(width: usize, height: usize, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// An image from row-major values; `None` when the length does not match.
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Loads a PNG or JPEG (grey or colour; colour is converted to luma).
    pub fn load(path: &Path) -> Result<Self, ImageLoadError> {
        let reader = image::ImageReader::open(path)
            .map_err(|source| ImageLoadError::Io {
                path: path.to_path_buf(),
                source,
            })?
            .with_guessed_format()
            .map_err(|source| ImageLoadError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        let decoded = reader.decode().map_err(|source| ImageLoadError::Decode {
            path: path.to_path_buf(),
            source,
        })?;
        let luma = decoded.into_luma8();
        let (w, h) = luma.dimensions();
        if w == 0 || h == 0 {
            return Err(ImageLoadError::Empty {
                path: path.to_path_buf(),
            });
        }
        Ok(Self::from_luma8(&luma))
    }

    /// From an 8-bit grey image of the `image` crate.
    pub fn from_luma8(img: &image::GrayImage) -> Self {
        let (w, h) = img.dimensions();
        Self {
            width: w as usize,
            height: h as usize,
            data: img.as_raw().iter().map(|&x| f32::from(x)).collect(),
        }
    }

    /// To an 8-bit grey image (rounded, clamped to 0..255).
    pub fn to_luma8(&self) -> image::GrayImage {
        let raw = self
            .data
            .iter()
            .map(|&x| x.round().clamp(0.0, 255.0) as u8)
            .collect();
        // Length matches by construction.
        image::GrayImage::from_raw(self.width as u32, self.height as u32, raw)
            .unwrap_or_else(|| image::GrayImage::new(self.width as u32, self.height as u32))
    }

    /// Width, pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Row-major values.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Mutable row-major values.
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// The value at integer coordinates, clamped to the border (replicate).
    #[inline]
    pub fn at_clamped(&self, x: isize, y: isize) -> f32 {
        let xc = x.clamp(0, self.width as isize - 1) as usize;
        let yc = y.clamp(0, self.height as isize - 1) as usize;
        self.data[yc * self.width + xc]
    }

    /// The value at integer coordinates inside the image.
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Bilinear sample at `(u, v)`, border replicated.
    #[inline]
    pub fn sample(&self, u: f64, v: f64) -> f32 {
        let (x0, y0) = (floor(u), floor(v));
        let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
        let inside =
            x0 >= 0 && y0 >= 0 && (x0 as usize) + 1 < self.width && (y0 as usize) + 1 < self.height;
        let (a, b, c, d) = if inside {
            let i = y0 as usize * self.width + x0 as usize;
            (
                self.data[i],
                self.data[i + 1],
                self.data[i + self.width],
                self.data[i + self.width + 1],
            )
        } else {
            (
                self.at_clamped(x0, y0),
                self.at_clamped(x0 + 1, y0),
                self.at_clamped(x0, y0 + 1),
                self.at_clamped(x0 + 1, y0 + 1),
            )
        };
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        top + (bottom - top) * fy
    }

    /// Half the size: each pixel the mean of a 2 x 2 block (an odd last row/column is
    /// dropped). Pixel `(i, j)` here is centred on `(2 i + 0.5, 2 j + 0.5)` of the original.
    pub fn half_size(&self) -> GrayImage {
        let (w, h) = (self.width / 2, self.height / 2);
        let mut data = vec![0.0f32; w * h];
        for (y, row) in data.chunks_mut(w.max(1)).enumerate().take(h) {
            let top = &self.data[2 * y * self.width..];
            let bottom = &self.data[(2 * y + 1) * self.width..];
            for (x, out) in row.iter_mut().enumerate() {
                *out = 0.25 * (top[2 * x] + top[2 * x + 1] + bottom[2 * x] + bottom[2 * x + 1]);
            }
        }
        GrayImage {
            width: w,
            height: h,
            data,
        }
    }

    /// Separable Gaussian blur (kernel radius `ceil(3 sigma)`, border replicated);
    /// a copy when `sigma <= 0`.
    pub fn gaussian_blur(&self, sigma: f64) -> GrayImage {
        if sigma <= 0.0 || self.data.is_empty() {
            return self.clone();
        }
        let radius = (3.0 * sigma).ceil() as isize;
        let mut kernel: Vec<f32> = (-radius..=radius)
            .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
            .collect();
        let sum: f32 = kernel.iter().sum();
        kernel.iter_mut().for_each(|k| *k /= sum);
        self.convolve_rows(&kernel).convolve_cols(&kernel)
    }

    /// Mean over a `(2r+1)^2` box, border replicated.
    pub fn box_mean(&self, r: usize) -> GrayImage {
        if self.data.is_empty() {
            return self.clone();
        }
        let kernel = vec![1.0 / (2 * r + 1) as f32; 2 * r + 1];
        self.convolve_rows(&kernel).convolve_cols(&kernel)
    }

    /// Horizontal convolution with an odd kernel, border replicated.
    fn convolve_rows(&self, kernel: &[f32]) -> GrayImage {
        let r = kernel.len() / 2;
        let w = self.width;
        let mut out = vec![0.0; self.data.len()];
        out.par_chunks_mut(w)
            .zip(self.data.par_chunks(w))
            .for_each_init(
                || vec![0.0f32; w + 2 * r],
                |padded, (row_out, row_in)| {
                    padded[r..r + w].copy_from_slice(row_in);
                    let (first, last) = (row_in[0], row_in[w - 1]);
                    padded[..r].iter_mut().for_each(|p| *p = first);
                    padded[r + w..].iter_mut().for_each(|p| *p = last);
                    for (k, &kv) in kernel.iter().enumerate() {
                        for (o, &p) in row_out.iter_mut().zip(&padded[k..k + w]) {
                            *o += kv * p;
                        }
                    }
                },
            );
        GrayImage {
            width: self.width,
            height: self.height,
            data: out,
        }
    }

    /// Vertical convolution with an odd kernel, border replicated.
    fn convolve_cols(&self, kernel: &[f32]) -> GrayImage {
        let r = kernel.len() / 2;
        let (w, h) = (self.width, self.height);
        let mut out = vec![0.0; self.data.len()];
        out.par_chunks_mut(w).enumerate().for_each(|(y, row_out)| {
            for (k, &kv) in kernel.iter().enumerate() {
                let ys = (y + k).saturating_sub(r).min(h - 1);
                let row_in = &self.data[ys * w..(ys + 1) * w];
                for (o, &p) in row_out.iter_mut().zip(row_in) {
                    *o += kv * p;
                }
            }
        });
        GrayImage {
            width: self.width,
            height: self.height,
            data: out,
        }
    }
}

/// `v.floor()` as an integer without a libm call (x86-64's baseline has no rounding
/// instruction); NaN gives 0 like `v.floor() as isize`.
#[inline]
pub(crate) fn floor(v: f64) -> isize {
    let t = v as isize;
    if (t as f64) > v {
        t - 1
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_sampling_uses_pixel_centres() {
        let img = GrayImage::from_vec(2, 1, vec![0.0, 10.0]).unwrap();
        assert!((img.sample(0.0, 0.0) - 0.0).abs() < 1e-6);
        assert!((img.sample(0.25, 0.0) - 2.5).abs() < 1e-6);
        assert!((img.sample(1.0, 0.0) - 10.0).abs() < 1e-6);
    }

    #[test]
    fn floor_matches_the_float_floor() {
        for v in [-2.5, -2.0, -1e-9, 0.0, 0.3, 1.0, 7.999, 1e6 + 0.5] {
            assert_eq!(floor(v), v.floor() as isize, "{v}");
        }
    }

    #[test]
    fn half_size_averages_2x2_blocks_centred_on_the_original_pixels() {
        let data: Vec<f32> = (0..5 * 3).map(|k| k as f32).collect();
        let img = GrayImage::from_vec(5, 3, data).unwrap();
        let half = img.half_size();
        assert_eq!((half.width(), half.height()), (2, 1));
        // Pixel (0, 1) averages (2, 0), (3, 0), (2, 1), (3, 1): its centre (2.5, 0.5).
        assert!((half.at(1, 0) - img.sample(2.5, 0.5)).abs() < 1e-6);
        assert!((half.at(0, 0) - 3.0).abs() < 1e-6);
    }

    #[test]
    fn blur_preserves_a_constant_image() {
        let img = GrayImage::new(7, 5, 42.0);
        let b = img.gaussian_blur(1.5);
        assert!(b.data().iter().all(|&x| (x - 42.0).abs() < 1e-3));
        assert_eq!((b.width(), b.height()), (7, 5));
    }
}
