//! The prior-map dataset (docs/formats.md section 2.9): the LiDAR map, the
//! optional satellite ortho image with its `satellite.yaml`, the camera and its first
//! image, `prior.yaml` and the optional `survey.csv`. Bad input is a [`PriorMapInputError`]
//! naming the file (and the line where there is one).

use std::path::{Path, PathBuf};

use msreg_estimator::camera::Camera;
use nalgebra::{Vector2, Vector3};
use serde::Deserialize;

use crate::camera_yaml::read_camera_yaml;
use crate::dataset::{read_camera_csv, DatasetError, CAMERA_CSV, CAMERA_YAML};
use crate::pointcloud::{read_pcd, PointCloud};
use crate::vision::GrayImage;

/// Why the dataset cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PriorMapInputError {
    /// A dataset file (CSV / YAML) is missing or malformed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// Any other file problem, with the file and (when known) the line.
    #[error("{}{}: {message}", .path.display(), .line.map(|l| format!(":{l}")).unwrap_or_default())]
    Bad {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
}

fn bad(path: &Path, line: Option<usize>, message: impl Into<String>) -> PriorMapInputError {
    PriorMapInputError::Bad {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// `map/satellite.yaml`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SatelliteYaml {
    /// Ground sampling (m per px).
    pub metres_per_pixel: f64,
    /// W (x, y) of the top-left pixel centre.
    pub top_left: [f64; 2],
}

/// A metric north-up ortho image.
#[derive(Clone, Debug)]
pub struct Satellite {
    /// The image (0-255).
    pub image: GrayImage,
    /// Its geometry.
    pub geo: SatelliteYaml,
}

impl Satellite {
    /// W (x, y) of pixel `(c, r)`.
    pub fn world_of(&self, px: &Vector2<f64>) -> Vector2<f64> {
        let m = self.geo.metres_per_pixel;
        Vector2::new(
            self.geo.top_left[0] + px.x * m,
            self.geo.top_left[1] - px.y * m,
        )
    }

    /// Pixel of W (x, y).
    pub fn pixel_of(&self, w: &Vector2<f64>) -> Vector2<f64> {
        let m = self.geo.metres_per_pixel;
        Vector2::new(
            (w.x - self.geo.top_left[0]) / m,
            (self.geo.top_left[1] - w.y) / m,
        )
    }
}

/// One user correspondence of `prior.yaml`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Correspondence {
    /// Pixel in the camera image.
    pub uv: [f64; 2],
    /// The point in W (m).
    pub xyz: [f64; 3],
}

/// `prior.yaml`.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorYaml {
    /// Camera position in W (GPS), m.
    pub position: Option<[f64; 3]>,
    /// Its 1-sigma per axis (m); default 5, 5, 3.
    pub sigma_position_m: Option<[f64; 3]>,
    /// Heading of the camera's x axis in W, deg from east towards north.
    pub yaw_deg: Option<f64>,
    /// Its 1-sigma (deg).
    pub sigma_yaw_deg: Option<f64>,
    /// Clicked correspondences.
    #[serde(default)]
    pub correspondences: Vec<Correspondence>,
}

/// A surveyed check point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Survey {
    /// In W (m).
    pub xyz: Vector3<f64>,
    /// Its pixel.
    pub uv: Vector2<f64>,
}

/// Everything the registration reads.
#[derive(Clone, Debug)]
pub struct PriorMapInput {
    /// The LiDAR map in W.
    pub map: PointCloud,
    /// The satellite image, if present.
    pub satellite: Option<Satellite>,
    /// The camera.
    pub camera: Camera<f64>,
    /// Its first image.
    pub image: GrayImage,
    /// The image file.
    pub image_path: PathBuf,
    /// The prior.
    pub prior: PriorYaml,
    /// Check points (empty without `survey.csv`).
    pub survey: Vec<Survey>,
}

/// Deserialises YAML `text` of `path`; errors name the line.
fn parse<T: serde::de::DeserializeOwned>(path: &Path, text: &str) -> Result<T, PriorMapInputError> {
    serde_yaml::from_str(text).map_err(|e| {
        let line = e.location().map(|l| l.line());
        bad(path, line, e.to_string())
    })
}

/// Reads `survey.csv`: `x, y, z, u, v` per line, `#` comments.
pub fn read_survey(path: &Path) -> Result<Vec<Survey>, PriorMapInputError> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, None, e.to_string()))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| bad(path, Some(i + 1), format!("not a number ({e})")))?;
        if v.len() != 5 || v.iter().any(|x| !x.is_finite()) {
            return Err(bad(
                path,
                Some(i + 1),
                format!("expected 5 finite columns x, y, z, u, v, got {}", v.len()),
            ));
        }
        out.push(Survey {
            xyz: Vector3::new(v[0], v[1], v[2]),
            uv: Vector2::new(v[3], v[4]),
        });
    }
    Ok(out)
}

/// Reads `prior.yaml`.
pub fn read_prior(path: &Path) -> Result<PriorYaml, PriorMapInputError> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, None, e.to_string()))?;
    let prior: PriorYaml = parse(path, &text)?;
    if prior.position.is_none() && prior.correspondences.len() < 4 {
        return Err(bad(
            path,
            None,
            "needs a position or at least 4 correspondences",
        ));
    }
    Ok(prior)
}

fn read_satellite(root: &Path) -> Result<Option<Satellite>, PriorMapInputError> {
    let png = root.join("map/satellite.png");
    if !png.exists() {
        return Ok(None);
    }
    let yaml = root.join("map/satellite.yaml");
    let text = std::fs::read_to_string(&yaml).map_err(|e| bad(&yaml, None, e.to_string()))?;
    let geo: SatelliteYaml = parse(&yaml, &text)?;
    if geo.metres_per_pixel.is_nan() || geo.metres_per_pixel <= 0.0 {
        return Err(bad(&yaml, None, "metres_per_pixel must be positive"));
    }
    let image = GrayImage::load(&png).map_err(|e| bad(&png, None, e.to_string()))?;
    Ok(Some(Satellite { image, geo }))
}

/// Reads the dataset under `root`.
pub fn read_input(root: &Path) -> Result<PriorMapInput, PriorMapInputError> {
    let pcd = root.join("map/map.pcd");
    let map = read_pcd(&pcd).map_err(|e| bad(&pcd, None, e.to_string()))?;
    let camera_yaml = root.join(CAMERA_YAML);
    let camera =
        read_camera_yaml(&camera_yaml).map_err(|e| bad(&camera_yaml, None, e.to_string()))?;
    let csv = root.join(CAMERA_CSV);
    let frames = read_camera_csv(&csv)?;
    let frame = frames
        .first()
        .ok_or_else(|| bad(&csv, None, "no image listed"))?;
    let image = GrayImage::load(&frame.path).map_err(|e| bad(&frame.path, None, e.to_string()))?;
    let survey_path = root.join("survey.csv");
    let survey = if survey_path.exists() {
        read_survey(&survey_path)?
    } else {
        Vec::new()
    };
    Ok(PriorMapInput {
        map,
        satellite: read_satellite(root)?,
        camera,
        image,
        image_path: frame.path.clone(),
        prior: read_prior(&root.join("prior.yaml"))?,
        survey,
    })
}
