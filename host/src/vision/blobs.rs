//! Bright-blob detection (the infrastructure cameras' LEDs or lit housings as the robot's
//! upward fisheye sees them, chapter 6): a fixed threshold, 8-connected components, an
//! intensity-weighted centroid (weights: grey level above the threshold), and gates on area,
//! elongation (ratio of the second-moment axes) and fill of the bounding box; optionally
//! only inside the fisheye's image circle.

use super::components::Labels;
use super::gray::GrayImage;

/// Blob detector settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobParams {
    /// Pixels brighter than this grey level belong to blobs.
    pub threshold: f32,
    /// Smallest blob, pixels.
    pub min_area: usize,
    /// Largest blob, pixels.
    pub max_area: usize,
    /// Largest ratio of the major to the minor second-moment axis.
    pub max_elongation: f64,
    /// Smallest fraction of the bounding box the blob fills.
    pub min_fill: f64,
    /// Only blobs whose centroid is inside this circle `(cx, cy, radius)`, pixels.
    pub image_circle: Option<(f64, f64, f64)>,
}

impl Default for BlobParams {
    fn default() -> Self {
        Self {
            threshold: 200.0,
            min_area: 3,
            max_area: 2000,
            max_elongation: 3.0,
            min_fill: 0.3,
            image_circle: None,
        }
    }
}

/// One bright blob.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blob {
    /// Intensity-weighted centroid, pixels (docs/formats.md pixel centres).
    pub u: f64,
    /// Intensity-weighted centroid, pixels.
    pub v: f64,
    /// Pixels above the threshold.
    pub area: usize,
    /// Brightest grey level.
    pub peak: f32,
}

/// The bright blobs of an image that pass the gates, in raster order of their first pixel.
pub fn detect_blobs(img: &GrayImage, params: &BlobParams) -> Vec<Blob> {
    let mask: Vec<bool> = img.data().iter().map(|&v| v > params.threshold).collect();
    let labels = Labels::new(&mask, img.width(), img.height());
    labels
        .components
        .iter()
        .enumerate()
        .filter(|(_, c)| (params.min_area..=params.max_area).contains(&c.area))
        .filter(|(_, c)| {
            let (w, h) = c.size();
            c.area as f64 >= params.min_fill * (w * h) as f64
        })
        .filter_map(|(k, c)| measure(img, &labels.pixels(k), params.threshold, c.area))
        .filter(|(blob, elongation)| {
            let inside = params
                .image_circle
                .is_none_or(|(cx, cy, r)| (blob.u - cx).powi(2) + (blob.v - cy).powi(2) <= r * r);
            inside && *elongation <= params.max_elongation
        })
        .map(|(blob, _)| blob)
        .collect()
}

/// The weighted centroid and elongation (sqrt of the second-moment eigenvalue ratio).
fn measure(
    img: &GrayImage,
    pixels: &[(usize, usize)],
    threshold: f32,
    area: usize,
) -> Option<(Blob, f64)> {
    let (mut sw, mut su, mut sv, mut peak) = (0.0, 0.0, 0.0, f32::MIN);
    for &(x, y) in pixels {
        let v = img.at(x, y);
        let w = f64::from(v - threshold).max(1e-3);
        sw += w;
        su += w * x as f64;
        sv += w * y as f64;
        peak = peak.max(v);
    }
    if sw <= 0.0 {
        return None;
    }
    let (u, v) = (su / sw, sv / sw);
    let (mut cuu, mut cuv, mut cvv) = (0.0, 0.0, 0.0);
    for &(x, y) in pixels {
        let (du, dv) = (x as f64 - u, y as f64 - v);
        cuu += du * du;
        cuv += du * dv;
        cvv += dv * dv;
    }
    let n = pixels.len() as f64;
    // Pixel extent (1/12 per axis) keeps one-pixel-wide blobs finite.
    let (cuu, cuv, cvv) = (cuu / n + 1.0 / 12.0, cuv / n, cvv / n + 1.0 / 12.0);
    let half_trace = 0.5 * (cuu + cvv);
    let root = (0.25 * (cuu - cvv).powi(2) + cuv * cuv).sqrt();
    let elongation = ((half_trace + root) / (half_trace - root).max(1e-12)).sqrt();
    Some((Blob { u, v, area, peak }, elongation))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gaussian spot of peak 250 on a background of 30.
    fn spot(img: &mut GrayImage, cx: f64, cy: f64, sigma_x: f64, sigma_y: f64) {
        let w = img.width();
        for (i, v) in img.data_mut().iter_mut().enumerate() {
            let (dx, dy) = ((i % w) as f64 - cx, (i / w) as f64 - cy);
            let g = (-(dx * dx) / (2.0 * sigma_x * sigma_x) - dy * dy / (2.0 * sigma_y * sigma_y))
                .exp();
            *v += (220.0 * g) as f32;
        }
    }

    #[test]
    fn finds_round_spots_to_sub_pixel_and_rejects_streaks_and_specks() {
        let mut img = GrayImage::new(120, 80, 30.0);
        spot(&mut img, 30.3, 40.7, 2.0, 2.0);
        spot(&mut img, 80.6, 20.2, 3.0, 3.0);
        spot(&mut img, 80.0, 60.0, 12.0, 1.2); // a streak
        img.data_mut()[5 * 120 + 100] = 255.0; // a one-pixel speck
        let blobs = detect_blobs(&img, &BlobParams::default());
        assert_eq!(blobs.len(), 2, "{blobs:?}");
        // Raster order: the spot at v = 20 first. Measured: 0.02 px (sigma 3), 0.05 px
        // (sigma 2, 6 pixels above the threshold).
        assert!(
            (blobs[0].u - 80.6).abs() < 0.1 && (blobs[0].v - 20.2).abs() < 0.1,
            "{blobs:?}"
        );
        assert!(
            (blobs[1].u - 30.3).abs() < 0.15 && (blobs[1].v - 40.7).abs() < 0.15,
            "{blobs:?}"
        );
        let circle = BlobParams {
            image_circle: Some((30.0, 40.0, 10.0)),
            ..BlobParams::default()
        };
        assert_eq!(detect_blobs(&img, &circle).len(), 1);
    }
}
