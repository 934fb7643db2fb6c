//! Readers of Kalibr's `camera.yaml` (one camchain entry, at top level or under a single
//! `camN:` key) into a [`Camera`], and of Kalibr's `target.yaml` into a [`Target`]
//! (docs/formats.md, section 2). Errors name the file and, where the YAML has one,
//! the line.

use std::path::{Path, PathBuf};

use msreg_estimator::camera::model::{CameraModel, ModelKind};
use msreg_estimator::camera::{
    equidistant::Equidistant, radtan::RadTan, Camera, Distortion, Intrinsics, Projection,
};
use nalgebra::Vector3;
use serde_yaml::{Mapping, Value};

/// Why a camera or target file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum YamlError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not YAML.
    #[error("{path}:{line}: malformed YAML: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when unknown).
        line: usize,
        /// The parser's message.
        message: String,
    },
    /// A key is missing or its value is wrong.
    #[error("{path}:{line}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the key (0 when it is missing).
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// A calibration target (Kalibr `target.yaml`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// `target_type: 'checkerboard'`.
    Checkerboard(CheckerboardTarget),
    /// `target_type: 'board'`: a plain rectangle, origin at its centre.
    Board(Board),
    /// Kalibr's `target_type: 'aprilgrid'`.
    AprilGrid(AprilGridTarget),
}

/// The plain rectangular board of `target.yaml` (`target_type: board`): origin at its
/// centre, x along `width_m`, y along `height_m`, z towards the viewer (docs/formats.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Board {
    /// Extent along target x, m.
    pub width_m: f64,
    /// Extent along target y, m.
    pub height_m: f64,
}

impl Board {
    /// Corners in the target frame, counter-clockwise seen from +z:
    /// `(-w/2, -h/2), (w/2, -h/2), (w/2, h/2), (-w/2, h/2)`. Edge `j` runs from corner `j`
    /// to corner `j + 1 (mod 4)`.
    pub fn corners(&self) -> [Vector3<f64>; 4] {
        let (x, y) = (0.5 * self.width_m, 0.5 * self.height_m);
        [
            Vector3::new(-x, -y, 0.0),
            Vector3::new(x, -y, 0.0),
            Vector3::new(x, y, 0.0),
            Vector3::new(-x, y, 0.0),
        ]
    }

    /// True when `(x, y)` of the board plane is on the board.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x.abs() <= 0.5 * self.width_m && y.abs() <= 0.5 * self.height_m
    }

    /// Length of the diagonal, m.
    pub fn diagonal(&self) -> f64 {
        self.width_m.hypot(self.height_m)
    }
}

impl Target {
    /// Corner `id` of a corner target (checkerboard or AprilGrid) in the target frame;
    /// `None` for an id outside it and for a plain board, which has no corners.
    pub fn corner(&self, id: usize) -> Option<nalgebra::Vector3<f64>> {
        match self {
            Self::Checkerboard(t) => (id < t.rows * t.cols).then(|| t.corner_in_target(id)),
            Self::AprilGrid(t) => t.corner(id),
            Self::Board { .. } => None,
        }
    }

    /// Number of corner ids (`0..n`): inner corners of a checkerboard, 4 per AprilGrid tag,
    /// none on a plain board.
    pub fn corner_count(&self) -> usize {
        match self {
            Self::Checkerboard(t) => t.rows * t.cols,
            Self::AprilGrid(t) => 4 * t.tag_cols * t.tag_rows,
            Self::Board { .. } => 0,
        }
    }
}

/// A Kalibr AprilGrid: `tag_cols x tag_rows` tags of side `tag_size_m`, `tag_spacing` (a
/// ratio of the tag size) apart. Corner id `4 i + k` is corner `k` (0..3 counter-clockwise
/// from the tag's bottom-left: (0, 0), (s, 0), (s, s), (0, s)) of tag `i`, which sits at
/// column `i % tag_cols`, row `i / tag_cols`, Kalibr's layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AprilGridTarget {
    /// `tagCols`.
    pub tag_cols: usize,
    /// `tagRows`.
    pub tag_rows: usize,
    /// `tagSize`, metres.
    pub tag_size_m: f64,
    /// `tagSpacing`: the gap between tags as a ratio of `tag_size_m`.
    pub tag_spacing: f64,
}

impl AprilGridTarget {
    /// Corner `id` in the target frame, `None` for an id outside the grid.
    pub fn corner(&self, id: usize) -> Option<nalgebra::Vector3<f64>> {
        let (tag, k) = (id / 4, id % 4);
        if tag >= self.tag_cols * self.tag_rows {
            return None;
        }
        let pitch = self.tag_size_m * (1.0 + self.tag_spacing);
        let (col, row) = ((tag % self.tag_cols) as f64, (tag / self.tag_cols) as f64);
        let s = self.tag_size_m;
        let (dx, dy) = [(0.0, 0.0), (s, 0.0), (s, s), (0.0, s)][k];
        Some(nalgebra::Vector3::new(
            col * pitch + dx,
            row * pitch + dy,
            0.0,
        ))
    }
}

/// A Kalibr checkerboard: corner id `r * cols + c` at `(r * row_spacing, c * col_spacing, 0)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckerboardTarget {
    /// `targetRows`: inner corner rows.
    pub rows: usize,
    /// `targetCols`: inner corner columns.
    pub cols: usize,
    /// `rowSpacingMeters`.
    pub row_spacing_m: f64,
    /// `colSpacingMeters`.
    pub col_spacing_m: f64,
    /// Physical board size (for LiDAR), centred on the pattern, if given.
    pub width_m: Option<f64>,
    /// Physical board height, if given.
    pub height_m: Option<f64>,
}

impl CheckerboardTarget {
    /// Corner `id` in the target frame, metres.
    pub fn corner_in_target(&self, id: usize) -> nalgebra::Vector3<f64> {
        let (r, c) = (id / self.cols, id % self.cols);
        nalgebra::Vector3::new(
            r as f64 * self.row_spacing_m,
            c as f64 * self.col_spacing_m,
            0.0,
        )
    }
}

/// A parsed file: its text (for line numbers) and root mapping.
struct Doc {
    path: PathBuf,
    text: String,
    root: Mapping,
}

impl Doc {
    fn read(path: &Path) -> Result<Self, YamlError> {
        let text = std::fs::read_to_string(path).map_err(|source| YamlError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(path, text)
    }

    fn parse(path: &Path, text: String) -> Result<Self, YamlError> {
        let value: Value = serde_yaml::from_str(&text).map_err(|e| YamlError::Syntax {
            path: path.to_path_buf(),
            line: e.location().map_or(0, |l| l.line()),
            message: e.to_string(),
        })?;
        let Value::Mapping(root) = value else {
            return Err(YamlError::Invalid {
                path: path.to_path_buf(),
                line: 1,
                message: "expected a mapping of keys".into(),
            });
        };
        Ok(Self {
            path: path.to_path_buf(),
            text,
            root,
        })
    }

    /// 1-based line of `key:` in the text (first occurrence), 0 when absent.
    fn line_of(&self, key: &str) -> usize {
        self.text
            .lines()
            .position(|l| {
                let t = l.trim_start().trim_start_matches(['"', '\'']);
                t.starts_with(key)
                    && t[key.len()..]
                        .trim_start_matches(['"', '\''])
                        .starts_with(':')
            })
            .map_or(0, |i| i + 1)
    }

    fn invalid(&self, key: &str, message: String) -> YamlError {
        YamlError::Invalid {
            path: self.path.clone(),
            line: self.line_of(key),
            message,
        }
    }

    /// A missing key is reported at line 1, where the top-level mapping it belongs in starts.
    fn get<'a>(&self, map: &'a Mapping, key: &str) -> Result<&'a Value, YamlError> {
        map.get(key).ok_or_else(|| YamlError::Invalid {
            path: self.path.clone(),
            line: 1,
            message: format!("missing key `{key}`"),
        })
    }

    fn string(&self, map: &Mapping, key: &str) -> Result<String, YamlError> {
        match self.get(map, key)? {
            Value::String(s) => Ok(s.trim().to_string()),
            _ => Err(self.invalid(key, format!("`{key}` must be a string"))),
        }
    }

    fn number(&self, map: &Mapping, key: &str) -> Result<f64, YamlError> {
        self.get(map, key)?
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.invalid(key, format!("`{key}` must be a finite number")))
    }

    fn numbers(&self, map: &Mapping, key: &str) -> Result<Vec<f64>, YamlError> {
        let Value::Sequence(seq) = self.get(map, key)? else {
            return Err(self.invalid(key, format!("`{key}` must be a list of numbers")));
        };
        seq.iter()
            .map(|v| v.as_f64().filter(|x| x.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| self.invalid(key, format!("`{key}` must be a list of finite numbers")))
    }

    fn count(&self, map: &Mapping, key: &str) -> Result<usize, YamlError> {
        self.get(map, key)?
            .as_u64()
            .map(|x| x as usize)
            .ok_or_else(|| self.invalid(key, format!("`{key}` must be a non-negative integer")))
    }
}

/// Reads a Kalibr `camera.yaml` (see the module docs).
pub fn read_camera_yaml(path: &Path) -> Result<Camera<f64>, YamlError> {
    camera_from_doc(&Doc::read(path)?)
}

/// Parses the text of a Kalibr `camera.yaml`; `path` only names it in errors.
pub fn parse_camera_yaml(path: &Path, text: &str) -> Result<Camera<f64>, YamlError> {
    camera_from_doc(&Doc::parse(path, text.to_string())?)
}

fn camera_from_doc(doc: &Doc) -> Result<Camera<f64>, YamlError> {
    // A single `camN:` wrapper is accepted.
    let map = match doc.root.get("camera_model") {
        Some(_) => &doc.root,
        None => match (doc.root.len(), doc.root.iter().next()) {
            (1, Some((_, Value::Mapping(inner)))) => inner,
            _ => return Err(doc.invalid("camera_model", "missing key `camera_model`".into())),
        },
    };
    let model = doc.string(map, "camera_model")?;
    let intr = doc.numbers(map, "intrinsics")?;
    let (projection, k) = match model.as_str() {
        "pinhole" => (
            Projection::Pinhole,
            expect_len(doc, "intrinsics", &intr, 4)?,
        ),
        "omni" => {
            let v = expect_len(doc, "intrinsics", &intr, 5)?;
            (Projection::Omni { xi: v[0] }, &v[1..])
        }
        "ds" | "eucm" => {
            return Err(doc.invalid(
                "camera_model",
                format!(
                    "camera_model `{model}` is calibrated by `msreg calibrate cameras` but not \
                     yet supported by this pipeline (supported: pinhole, omni)"
                ),
            ))
        }
        other => {
            return Err(doc.invalid(
                "camera_model",
                format!("unknown camera_model `{other}` (expected pinhole or omni)"),
            ))
        }
    };
    let intrinsics = Intrinsics {
        fu: k[0],
        fv: k[1],
        cu: k[2],
        cv: k[3],
    };
    let distortion = distortion(doc, map)?;
    let res = doc.numbers(map, "resolution")?;
    let res = expect_len(doc, "resolution", &res, 2)?;
    if res
        .iter()
        .any(|&x| x < 1.0 || x.fract() != 0.0 || x > f64::from(u32::MAX))
    {
        return Err(doc.invalid(
            "resolution",
            "`resolution` must be two positive integers".into(),
        ));
    }
    Camera::new(
        projection,
        intrinsics,
        distortion,
        (res[0] as u32, res[1] as u32),
    )
    .map_err(|e| {
        doc.invalid(
            "camera_model",
            format!(
                "invalid camera ({e:?}): focal lengths must be positive, omni takes radtan or none"
            ),
        )
    })
}

fn distortion(doc: &Doc, map: &Mapping) -> Result<Distortion<f64>, YamlError> {
    let model = match map.get("distortion_model") {
        None => return Ok(Distortion::None),
        Some(_) => doc.string(map, "distortion_model")?,
    };
    let coeffs = match map.get("distortion_coeffs") {
        None | Some(Value::Null) if model != "none" => {
            // Reported at the model's line: the key itself is absent (a typo is named by
            // `msreg check`'s unknown-key warning).
            return Err(doc.invalid(
                "distortion_model",
                format!("missing key `distortion_coeffs` (distortion_model `{model}` needs it)"),
            ));
        }
        None | Some(Value::Null) => Vec::new(),
        Some(_) => doc.numbers(map, "distortion_coeffs")?,
    };
    let key = "distortion_coeffs";
    match model.as_str() {
        "none" => Ok(Distortion::None),
        "radtan" | "plumb_bob" => match coeffs.len() {
            4 | 5 => Ok(Distortion::RadTan(RadTan {
                k1: coeffs[0],
                k2: coeffs[1],
                p1: coeffs[2],
                p2: coeffs[3],
                k3: coeffs.get(4).copied().unwrap_or(0.0),
            })),
            n => Err(doc.invalid(key, format!("radtan takes 4 (or 5) coefficients, got {n}"))),
        },
        "equidistant" => {
            let c = expect_len(doc, key, &coeffs, 4)?;
            Ok(Distortion::Equidistant(Equidistant {
                k1: c[0],
                k2: c[1],
                k3: c[2],
                k4: c[3],
            }))
        }
        other => Err(doc.invalid(
            "distortion_model",
            format!("unknown distortion_model `{other}` (expected radtan, equidistant or none)"),
        )),
    }
}

fn expect_len<'a>(doc: &Doc, key: &str, v: &'a [f64], n: usize) -> Result<&'a [f64], YamlError> {
    if v.len() == n {
        Ok(v)
    } else {
        Err(doc.invalid(key, format!("`{key}` needs {n} values, got {}", v.len())))
    }
}

/// Reads a Kalibr `target.yaml` (checkerboard or plain board).
pub fn read_target_yaml(path: &Path) -> Result<Target, YamlError> {
    target_from_doc(&Doc::read(path)?)
}

/// Parses the text of a `target.yaml`; `path` only names it in errors.
pub fn parse_target_yaml(path: &Path, text: &str) -> Result<Target, YamlError> {
    target_from_doc(&Doc::parse(path, text.to_string())?)
}

fn target_from_doc(doc: &Doc) -> Result<Target, YamlError> {
    let map = &doc.root;
    let kind = match map.get("target_type") {
        Some(_) => doc.string(map, "target_type")?,
        None if map.contains_key("targetRows") => "checkerboard".to_string(),
        None => return Err(doc.invalid("target_type", "missing key `target_type`".into())),
    };
    let positive = |key: &str| -> Result<f64, YamlError> {
        let x = doc.number(map, key)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(doc.invalid(key, format!("`{key}` must be positive")))
        }
    };
    let optional = |key: &str| -> Result<Option<f64>, YamlError> {
        if map.contains_key(key) {
            positive(key).map(Some)
        } else {
            Ok(None)
        }
    };
    match kind.as_str() {
        "checkerboard" => {
            let rows = doc.count(map, "targetRows")?;
            let cols = doc.count(map, "targetCols")?;
            for (key, n) in [("targetRows", rows), ("targetCols", cols)] {
                if n < 3 {
                    return Err(doc.invalid(
                        key,
                        format!("`{key}` is {n}: at least 3 inner corners are needed"),
                    ));
                }
            }
            Ok(Target::Checkerboard(CheckerboardTarget {
                rows,
                cols,
                row_spacing_m: positive("rowSpacingMeters")?,
                col_spacing_m: positive("colSpacingMeters")?,
                width_m: optional("width_m")?,
                height_m: optional("height_m")?,
            }))
        }
        "board" => Ok(Target::Board(Board {
            width_m: positive("width_m")?,
            height_m: positive("height_m")?,
        })),
        "aprilgrid" => {
            let grid = || -> Result<AprilGridTarget, YamlError> {
                Ok(AprilGridTarget {
                    tag_cols: doc.count(map, "tagCols")?,
                    tag_rows: doc.count(map, "tagRows")?,
                    tag_size_m: positive("tagSize")?,
                    tag_spacing: positive("tagSpacing")?,
                })
            };
            grid().map(Target::AprilGrid).map_err(|e| match e {
                YamlError::Invalid {
                    path,
                    line,
                    message,
                } => YamlError::Invalid {
                    path,
                    line,
                    message: format!(
                        "{message} (an aprilgrid target needs tagCols, tagRows, tagSize and \
                         tagSpacing)"
                    ),
                },
                other => other,
            })
        }
        other => Err(doc.invalid(
            "target_type",
            format!(
                "unsupported target_type `{other}` (expected checkerboard, aprilgrid or board)"
            ),
        )),
    }
}

/// A YAML float that both serde_yaml and PyYAML (Kalibr) read back exactly: shortest
/// digits, a `.` in the mantissa and a signed exponent.
fn yaml_float(x: f64) -> String {
    let debug = format!("{x:?}");
    match debug.split_once('e') {
        None => debug,
        Some((m, e)) => {
            let m = if m.contains('.') {
                m.to_string()
            } else {
                format!("{m}.0")
            };
            let e = if e.starts_with('-') {
                e.to_string()
            } else {
                format!("+{e}")
            };
            format!("{m}e{e}")
        }
    }
}

fn yaml_list(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|&v| yaml_float(v)).collect();
    format!("[{}]", items.join(", "))
}

/// Kalibr `camera.yaml` text of `camera` (one camchain entry at top level), as
/// [`read_camera_yaml`] reads it back.
pub fn camera_yaml_string(camera: &Camera<f64>) -> String {
    let i = camera.intrinsics();
    let (model, intrinsics) = match camera.projection() {
        Projection::Pinhole => ("pinhole", vec![i.fu, i.fv, i.cu, i.cv]),
        Projection::Omni { xi } => ("omni", vec![*xi, i.fu, i.fv, i.cu, i.cv]),
    };
    let (distortion, coeffs) = match camera.distortion() {
        Distortion::None => ("none", vec![]),
        Distortion::RadTan(d) if d.k3 == 0.0 => ("radtan", vec![d.k1, d.k2, d.p1, d.p2]),
        Distortion::RadTan(d) => ("radtan", vec![d.k1, d.k2, d.p1, d.p2, d.k3]),
        Distortion::Equidistant(d) => ("equidistant", vec![d.k1, d.k2, d.k3, d.k4]),
    };
    format!(
        "# Kalibr camchain entry\ncamera_model: {model}\nintrinsics: {}\n\
         distortion_model: {distortion}\ndistortion_coeffs: {}\nresolution: [{}, {}]\n",
        yaml_list(&intrinsics),
        yaml_list(&coeffs),
        camera.resolution.0,
        camera.resolution.1
    )
}

/// A `camera.yaml` for intrinsic calibration: the model and resolution, and the intrinsics
/// when the file has them (docs/formats.md, sections 2 and 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    /// The model of `camera_model` / `distortion_model` (distortion absent: `none`).
    pub kind: ModelKind,
    /// `resolution`.
    pub resolution: (u32, u32),
    /// The full model when `intrinsics` (and the coefficients) are given.
    pub model: Option<CameraModel<f64>>,
}

/// Reads a `camera.yaml` of any Kalibr model (`pinhole`, `omni`, `ds`, `eucm`), where
/// `intrinsics` and `distortion_coeffs` are optional.
pub fn read_camera_spec(path: &Path) -> Result<CameraSpec, YamlError> {
    let doc = Doc::read(path)?;
    let map = match doc.root.get("camera_model") {
        Some(_) => &doc.root,
        None => match (doc.root.len(), doc.root.iter().next()) {
            (1, Some((_, Value::Mapping(inner)))) => inner,
            _ => return Err(doc.invalid("camera_model", "missing key `camera_model`".into())),
        },
    };
    let model = doc.string(map, "camera_model")?;
    let distortion = match map.get("distortion_model") {
        None => "none".to_string(),
        Some(_) => doc.string(map, "distortion_model")?,
    };
    let kind = ModelKind::from_kalibr(&model, &distortion).ok_or_else(|| {
        doc.invalid(
            "camera_model",
            format!(
                "unsupported model `{model}` with distortion `{distortion}` (expected pinhole \
                 with radtan or equidistant, omni with radtan, ds or eucm with none)"
            ),
        )
    })?;
    let res = doc.numbers(map, "resolution")?;
    let res = expect_len(&doc, "resolution", &res, 2)?;
    if res
        .iter()
        .any(|&x| x < 1.0 || x.fract() != 0.0 || x > f64::from(u32::MAX))
    {
        return Err(doc.invalid(
            "resolution",
            "`resolution` must be two positive integers".into(),
        ));
    }
    let resolution = (res[0] as u32, res[1] as u32);
    let model =
        match map.get("intrinsics") {
            None | Some(Value::Null) => None,
            Some(_) => {
                let mut values = doc.numbers(map, "intrinsics")?;
                expect_len(&doc, "intrinsics", &values, kind.intrinsic_count())?;
                let coeffs = match map.get("distortion_coeffs") {
                    None | Some(Value::Null) => Vec::new(),
                    Some(_) => doc.numbers(map, "distortion_coeffs")?,
                };
                let n = kind.param_count() - kind.intrinsic_count();
                // A pinhole `none` is radtan with zero coefficients.
                let coeffs = if coeffs.is_empty() {
                    vec![0.0; n]
                } else {
                    coeffs
                };
                values.extend(expect_len(&doc, "distortion_coeffs", &coeffs, n)?);
                Some(CameraModel::new(kind, &values, resolution).map_err(|e| {
                    doc.invalid("intrinsics", format!("invalid intrinsics ({e:?})"))
                })?)
            }
        };
    Ok(CameraSpec {
        kind,
        resolution,
        model,
    })
}

/// Kalibr `camera.yaml` text of a model of any kind, as [`read_camera_spec`] (and, for
/// pinhole and omni, [`read_camera_yaml`]) reads it back.
pub fn camera_model_yaml_string(model: &CameraModel<f64>) -> String {
    let v = model.values();
    let k = model.kind.intrinsic_count();
    format!(
        "# Kalibr camchain entry\ncamera_model: {}\nintrinsics: {}\n\
         distortion_model: {}\ndistortion_coeffs: {}\nresolution: [{}, {}]\n",
        model.kind.camera_model(),
        yaml_list(&v[..k]),
        model.kind.distortion_model(),
        yaml_list(&v[k..]),
        model.resolution.0,
        model.resolution.1
    )
}

/// [`yaml_float`] for other writers of Kalibr-compatible YAML.
pub fn yaml_number(x: f64) -> String {
    yaml_float(x)
}

/// Kalibr `target.yaml` text of a checkerboard, as [`read_target_yaml`] reads it back.
pub fn checkerboard_yaml_string(target: &CheckerboardTarget) -> String {
    let mut text = format!(
        "target_type: 'checkerboard'\ntargetCols: {}\ntargetRows: {}\n\
         colSpacingMeters: {}\nrowSpacingMeters: {}\n",
        target.cols,
        target.rows,
        yaml_float(target.col_spacing_m),
        yaml_float(target.row_spacing_m)
    );
    for (key, value) in [("width_m", target.width_m), ("height_m", target.height_m)] {
        if let Some(v) = value {
            text.push_str(&format!("{key}: {}\n", yaml_float(v)));
        }
    }
    text
}

/// Kalibr-style `target.yaml` text of a plain board, as [`read_target_yaml`] reads it back.
pub fn board_yaml_string(board: &Board) -> String {
    format!(
        "target_type: 'board'\nwidth_m: {}\nheight_m: {}\n",
        board.width_m, board.height_m
    )
}

/// Kalibr's `target.yaml` text of an AprilGrid.
pub fn aprilgrid_yaml_string(target: &AprilGridTarget) -> String {
    format!(
        "target_type: 'aprilgrid'\ntagCols: {}\ntagRows: {}\ntagSize: {}\ntagSpacing: {}\n",
        target.tag_cols,
        target.tag_rows,
        yaml_float(target.tag_size_m),
        yaml_float(target.tag_spacing)
    )
}
