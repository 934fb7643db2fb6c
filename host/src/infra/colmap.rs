//! COLMAP text model (`cameras.txt`, `images.txt`, `points3D.txt`) of the VO keyframes of
//! `F`: one reader and one writer. COLMAP's pixel convention (top-left pixel centre at
//! (0.5, 0.5)) is converted at the file boundary: inside msreg every pixel is OpenCV's.
//! Poses are COLMAP's world-to-camera `T_cam_world` (qvec w x y z, tvec); image NAME is
//! `<timestamp_ns>.png`. Camera models read: OPENCV_FISHEYE (equidistant), PINHOLE,
//! SIMPLE_PINHOLE, OPENCV (radtan); one camera (the VO's `F`).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use msreg_estimator::camera::{
    equidistant::Equidistant, radtan::RadTan, Camera, Distortion, Intrinsics, Projection,
};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector2, Vector3};

use super::io::InfraError;

/// One keyframe of the model.
#[derive(Clone, Debug)]
pub struct ColmapImage {
    /// COLMAP IMAGE_ID.
    pub id: u32,
    /// Stamp from the NAME `<timestamp_ns>.png`.
    pub stamp_ns: u64,
    /// `T_cam_world` in VO units.
    pub t_cam_world: Isometry3<f64>,
    /// Keypoints (OpenCV pixels) and the index into [`ColmapModel::points`] of their 3D
    /// point, if any.
    pub keypoints: Vec<(Vector2<f64>, Option<usize>)>,
}

/// The model: the camera, keyframes sorted by stamp, points (VO units).
#[derive(Clone, Debug)]
pub struct ColmapModel {
    /// Intrinsics of the VO camera (OpenCV pixels).
    pub camera: Camera<f64>,
    /// Keyframes, ascending stamps.
    pub images: Vec<ColmapImage>,
    /// 3D points in the VO world.
    pub points: Vec<Vector3<f64>>,
}

fn bad(path: &Path, line: usize, message: impl Into<String>) -> InfraError {
    InfraError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn read(path: &Path) -> Result<String, InfraError> {
    std::fs::read_to_string(path).map_err(|source| InfraError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Data lines (1-based line number, fields), comments and blank lines skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let l = l.trim();
        (!l.is_empty() && !l.starts_with('#')).then(|| (i + 1, l.split_whitespace().collect()))
    })
}

fn numbers(path: &Path, line: usize, fields: &[&str]) -> Result<Vec<f64>, InfraError> {
    fields
        .iter()
        .map(|f| {
            f.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(path, line, format!("`{f}` is not a finite number")))
        })
        .collect()
}

/// Camera of a `cameras.txt` line (COLMAP pixels converted to OpenCV's).
fn parse_camera(path: &Path, line: usize, f: &[&str]) -> Result<Camera<f64>, InfraError> {
    if f.len() < 5 {
        return Err(bad(
            path,
            line,
            "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]",
        ));
    }
    let (w, h) = match (f[2].parse::<u32>(), f[3].parse::<u32>()) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 => (w, h),
        _ => {
            return Err(bad(
                path,
                line,
                "WIDTH and HEIGHT must be positive integers",
            ))
        }
    };
    let p = numbers(path, line, &f[4..])?;
    let need = |n: usize| {
        (p.len() == n).then_some(()).ok_or_else(|| {
            bad(
                path,
                line,
                format!("model {} takes {n} parameters, got {}", f[1], p.len()),
            )
        })
    };
    let k = |fu: f64, fv: f64, cu: f64, cv: f64| Intrinsics {
        fu,
        fv,
        cu: cu - 0.5,
        cv: cv - 0.5,
    };
    let (intr, dist) = match f[1] {
        "SIMPLE_PINHOLE" => {
            need(3)?;
            (k(p[0], p[0], p[1], p[2]), Distortion::None)
        }
        "PINHOLE" => {
            need(4)?;
            (k(p[0], p[1], p[2], p[3]), Distortion::None)
        }
        "OPENCV" => {
            need(8)?;
            let d = RadTan { k1: p[4], k2: p[5], p1: p[6], p2: p[7], k3: 0.0 };
            (k(p[0], p[1], p[2], p[3]), Distortion::RadTan(d))
        }
        "OPENCV_FISHEYE" => {
            need(8)?;
            let d = Equidistant { k1: p[4], k2: p[5], k3: p[6], k4: p[7] };
            (k(p[0], p[1], p[2], p[3]), Distortion::Equidistant(d))
        }
        other => {
            return Err(bad(
                path,
                line,
                format!("camera model `{other}` unsupported (OPENCV_FISHEYE, PINHOLE, SIMPLE_PINHOLE, OPENCV)"),
            ))
        }
    };
    Camera::new(Projection::Pinhole, intr, dist, (w, h))
        .map_err(|e| bad(path, line, format!("invalid camera: {e:?}")))
}

fn read_cameras(dir: &Path) -> Result<(u32, Camera<f64>), InfraError> {
    let path = dir.join("cameras.txt");
    let text = read(&path)?;
    let mut found = None;
    for (line, f) in data_lines(&text) {
        if found.is_some() {
            return Err(bad(
                &path,
                line,
                "more than one camera: the VO model must have one (F)",
            ));
        }
        let id = f[0]
            .parse::<u32>()
            .map_err(|_| bad(&path, line, "CAMERA_ID must be an integer"))?;
        found = Some((id, parse_camera(&path, line, &f)?));
    }
    found.ok_or_else(|| bad(&path, 0, "no camera"))
}

/// Pose line of `images.txt`: (IMAGE_ID, stamp, T_cam_world, CAMERA_ID).
fn parse_image_line(
    path: &Path,
    line: usize,
    f: &[&str],
) -> Result<(u32, u64, Isometry3<f64>, u32), InfraError> {
    if f.len() != 10 {
        return Err(bad(
            path,
            line,
            "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
        ));
    }
    let id = f[0]
        .parse::<u32>()
        .map_err(|_| bad(path, line, "IMAGE_ID must be an integer"))?;
    let v = numbers(path, line, &f[1..8])?;
    let q = Quaternion::new(v[0], v[1], v[2], v[3]);
    if (q.norm() - 1.0).abs() > 1e-3 {
        return Err(bad(
            path,
            line,
            format!("qvec has norm {} (expected 1)", q.norm()),
        ));
    }
    let cam = f[8]
        .parse::<u32>()
        .map_err(|_| bad(path, line, "CAMERA_ID must be an integer"))?;
    let stamp = f[9]
        .rsplit('/')
        .next()
        .and_then(|n| n.split('.').next())
        .and_then(|s| s.parse::<u64>().ok())
        .ok_or_else(|| {
            bad(
                path,
                line,
                format!("NAME `{}` is not <timestamp_ns>.png", f[9]),
            )
        })?;
    let pose = Isometry3::from_parts(
        Translation3::new(v[4], v[5], v[6]),
        UnitQuaternion::from_quaternion(q),
    );
    Ok((id, stamp, pose, cam))
}

type RawKeypoints = Vec<(Vector2<f64>, i64)>;

fn parse_keypoints(path: &Path, line: usize, f: &[&str]) -> Result<RawKeypoints, InfraError> {
    if f.len() % 3 != 0 {
        return Err(bad(path, line, "POINTS2D must be triples X Y POINT3D_ID"));
    }
    f.chunks(3)
        .map(|c| {
            let xy = numbers(path, line, &c[..2])?;
            let pid = c[2].parse::<i64>().map_err(|_| {
                bad(
                    path,
                    line,
                    format!("POINT3D_ID `{}` is not an integer", c[2]),
                )
            })?;
            Ok((Vector2::new(xy[0] - 0.5, xy[1] - 0.5), pid))
        })
        .collect()
}

fn read_images(dir: &Path, camera_id: u32) -> Result<Vec<(ColmapImage, RawKeypoints)>, InfraError> {
    let path = dir.join("images.txt");
    let text = read(&path)?;
    // Pose lines and keypoint lines alternate; an empty keypoint line is blank, so pair
    // by raw line numbers rather than by data lines.
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i].trim();
        if l.is_empty() || l.starts_with('#') {
            i += 1;
            continue;
        }
        let f: Vec<&str> = l.split_whitespace().collect();
        let (id, stamp_ns, t_cam_world, cam) = parse_image_line(&path, i + 1, &f)?;
        if cam != camera_id {
            return Err(bad(
                &path,
                i + 1,
                format!("CAMERA_ID {cam} is not the model's camera {camera_id}"),
            ));
        }
        let kp_line = lines.get(i + 1).copied().unwrap_or("");
        let kp: Vec<&str> = kp_line.split_whitespace().collect();
        let raw = parse_keypoints(&path, i + 2, &kp)?;
        out.push((
            ColmapImage {
                id,
                stamp_ns,
                t_cam_world,
                keypoints: Vec::new(),
            },
            raw,
        ));
        i += 2;
    }
    Ok(out)
}

fn read_points(dir: &Path) -> Result<HashMap<i64, (usize, Vector3<f64>)>, InfraError> {
    let path = dir.join("points3D.txt");
    let text = read(&path)?;
    let mut out = HashMap::new();
    for (line, f) in data_lines(&text) {
        if f.len() < 8 {
            return Err(bad(
                &path,
                line,
                "expected POINT3D_ID X Y Z R G B ERROR TRACK[]",
            ));
        }
        let id = f[0]
            .parse::<i64>()
            .map_err(|_| bad(&path, line, "POINT3D_ID must be an integer"))?;
        let v = numbers(&path, line, &f[1..4])?;
        let idx = out.len();
        if out
            .insert(id, (idx, Vector3::new(v[0], v[1], v[2])))
            .is_some()
        {
            return Err(bad(&path, line, format!("duplicate POINT3D_ID {id}")));
        }
    }
    Ok(out)
}

/// Reads `dir/{cameras,images,points3D}.txt`.
pub fn read_model(dir: &Path) -> Result<ColmapModel, InfraError> {
    let (camera_id, camera) = read_cameras(dir)?;
    let raw_images = read_images(dir, camera_id)?;
    let points_by_id = read_points(dir)?;
    let mut points = vec![Vector3::zeros(); points_by_id.len()];
    for (idx, p) in points_by_id.values() {
        points[*idx] = *p;
    }
    let images_path: PathBuf = dir.join("images.txt");
    let mut images = Vec::with_capacity(raw_images.len());
    for (mut image, raw) in raw_images {
        for (uv, pid) in raw {
            let point = match pid {
                -1 => None,
                id => Some(points_by_id.get(&id).map(|(i, _)| *i).ok_or_else(|| {
                    bad(
                        &images_path,
                        0,
                        format!(
                            "image {} refers to POINT3D_ID {id}, absent from points3D.txt",
                            image.id
                        ),
                    )
                })?),
            };
            image.keypoints.push((uv, point));
        }
        images.push(image);
    }
    images.sort_by_key(|i| i.stamp_ns);
    if images.windows(2).any(|w| w[0].stamp_ns == w[1].stamp_ns) {
        return Err(bad(&images_path, 0, "two images share a timestamp"));
    }
    Ok(ColmapModel {
        camera,
        images,
        points,
    })
}

fn camera_line(c: &Camera<f64>) -> String {
    let i = c.intrinsics();
    let (w, h) = c.resolution;
    let (cu, cv) = (i.cu + 0.5, i.cv + 0.5);
    match c.distortion() {
        Distortion::Equidistant(d) => format!(
            "1 OPENCV_FISHEYE {w} {h} {} {} {cu} {cv} {} {} {} {}",
            i.fu, i.fv, d.k1, d.k2, d.k3, d.k4
        ),
        Distortion::RadTan(d) => format!(
            "1 OPENCV {w} {h} {} {} {cu} {cv} {} {} {} {}",
            i.fu, i.fv, d.k1, d.k2, d.p1, d.p2
        ),
        Distortion::None => format!("1 PINHOLE {w} {h} {} {} {cu} {cv}", i.fu, i.fv),
    }
}

/// Writes the model as COLMAP text into `dir` (created).
pub fn write_model(dir: &Path, model: &ColmapModel) -> Result<(), InfraError> {
    let io = |source| InfraError::Io {
        path: dir.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(io)?;
    let cams = format!("# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n{}\n", camera_line(&model.camera));
    let mut tracks: Vec<Vec<(u32, usize)>> = vec![Vec::new(); model.points.len()];
    let mut imgs = String::from("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    for im in &model.images {
        let q = im.t_cam_world.rotation.quaternion();
        let t = im.t_cam_world.translation.vector;
        let _ = writeln!(
            imgs,
            "{} {} {} {} {} {} {} {} 1 {}.png",
            im.id, q.w, q.i, q.j, q.k, t.x, t.y, t.z, im.stamp_ns
        );
        let kps: Vec<String> = im
            .keypoints
            .iter()
            .enumerate()
            .map(|(n, (uv, pid))| {
                if let Some(p) = pid {
                    tracks[*p].push((im.id, n));
                }
                let id = pid.map_or(-1, |p| p as i64 + 1);
                format!("{} {} {id}", uv.x + 0.5, uv.y + 0.5)
            })
            .collect();
        let _ = writeln!(imgs, "{}", kps.join(" "));
    }
    let mut pts =
        String::from("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    for (j, p) in model.points.iter().enumerate() {
        let tr: Vec<String> = tracks[j].iter().map(|(i, n)| format!("{i} {n}")).collect();
        let _ = writeln!(
            pts,
            "{} {} {} {} 128 128 128 0.5 {}",
            j + 1,
            p.x,
            p.y,
            p.z,
            tr.join(" ")
        );
    }
    for (name, text) in [
        ("cameras.txt", cams),
        ("images.txt", imgs),
        ("points3D.txt", pts),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|source| InfraError::Io { path, source })?;
    }
    Ok(())
}
