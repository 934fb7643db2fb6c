//! Drawing over a camera image: the image in grey as an RGB canvas, dots at pixels.

use std::path::Path;

use nalgebra::Vector2;

use super::GrayImage;

/// An RGB copy of a grey image to draw on.
pub struct Canvas(image::RgbImage);

impl Canvas {
    /// The image in grey, as RGB.
    pub fn from_gray(image: &GrayImage) -> Self {
        let grey = image.to_luma8();
        Self(image::RgbImage::from_fn(
            grey.width(),
            grey.height(),
            |x, y| {
                let v = grey.get_pixel(x, y).0[0];
                image::Rgb([v, v, v])
            },
        ))
    }

    /// A square dot of half-width `radius` pixels centred at `pixel` (clipped at the image
    /// border).
    pub fn dot(&mut self, pixel: &Vector2<f64>, colour: [u8; 3], radius: i64) {
        let (u, v) = (pixel.x.round() as i64, pixel.y.round() as i64);
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                let (x, y) = (u + dx, v + dy);
                if x >= 0 && y >= 0 && (x as u32) < self.0.width() && (y as u32) < self.0.height() {
                    self.0.put_pixel(x as u32, y as u32, image::Rgb(colour));
                }
            }
        }
    }

    /// Writes the canvas (format from the extension).
    pub fn save(&self, path: &Path) -> Result<(), image::ImageError> {
        self.0.save(path)
    }
}
