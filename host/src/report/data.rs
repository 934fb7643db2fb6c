//! What the figures read from a pipeline's JSON report: the pipeline kind, the filter's
//! convergence history, the final estimate with its sigmas, and the residual series.
//! Read from `serde_json::Value` so one renderer serves every report type; NaN is written
//! as `null` by serde_json and read back as NaN.

use nalgebra::{Matrix3, Rotation3};
use serde_json::Value;

/// Which pipeline wrote the report (recognised from its fields).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `calibrate pose-imu`.
    PoseImu,
    /// `calibrate lidar-imu`.
    LidarImu,
    /// `calibrate camera-imu`.
    CameraImu,
    /// `calibrate lidar-camera` (target-based).
    LidarCamera,
    /// `calibrate lidar-camera --targetless` (mutual information).
    Targetless,
    /// `calibrate infra`.
    Infra,
    /// `calibrate prior-map` (a static camera in a prior map, mutual information).
    PriorMap,
    /// `monitor` (the health monitor replayed over a drive).
    Monitor,
    /// `calibrate joint` (LiDAR, camera and IMU in one filter).
    Joint,
    /// Anything else: only the generic tables.
    Other,
}

impl Kind {
    /// Recognises the pipeline from the report's fields.
    pub fn of(report: &Value) -> Kind {
        let has = |k: &str| report.get(k).is_some();
        if has("history") && has("scans_total") {
            Kind::LidarImu
        } else if has("history") && has("pixel_sigma") {
            Kind::CameraImu
        } else if has("history") {
            Kind::PoseImu
        } else if has("camera") && has("lidar") && has("planes") {
            Kind::Joint
        } else if has("sensors") && has("alarms") {
            Kind::Monitor
        } else if has("mi_slices") && has("t_world_cam") {
            Kind::PriorMap
        } else if has("nmi") && has("t_cam_lidar") {
            Kind::Targetless
        } else if has("frames_total") && has("method") {
            Kind::LidarCamera
        } else if has("stages") && has("cameras") {
            Kind::Infra
        } else {
            Kind::Other
        }
    }

    /// Title of the page.
    pub fn title(self) -> &'static str {
        match self {
            Kind::PoseImu => "pose-IMU calibration",
            Kind::LidarImu => "LiDAR-IMU calibration",
            Kind::CameraImu => "camera-IMU calibration",
            Kind::LidarCamera => "LiDAR-camera calibration",
            Kind::Targetless => "LiDAR-camera calibration (targetless, mutual information)",
            Kind::Infra => "infrastructure-camera calibration",
            Kind::PriorMap => "camera in a prior map (mutual information)",
            Kind::Monitor => "on-vehicle calibration monitoring",
            Kind::Joint => "joint LiDAR-IMU-camera calibration",
            Kind::Other => "msreg report",
        }
    }

    /// Name of the estimated transform.
    pub fn transform(self) -> &'static str {
        match self {
            Kind::PoseImu => "T_imu_pose",
            Kind::LidarImu => "T_imu_lidar",
            Kind::CameraImu => "T_imu_cam",
            Kind::LidarCamera | Kind::Targetless => "T_cam_lidar",
            Kind::PriorMap => "T_world_cam",
            Kind::Infra | Kind::Monitor | Kind::Joint | Kind::Other => "",
        }
    }
}

/// A number (NaN for `null` or a missing field).
pub fn num(v: Option<&Value>) -> f64 {
    v.and_then(Value::as_f64).unwrap_or(f64::NAN)
}

/// A fixed-size numeric array (NaN where missing).
pub fn nums<const N: usize>(v: Option<&Value>) -> [f64; N] {
    std::array::from_fn(|i| num(v.and_then(|a| a.get(i))))
}

/// Names and display units of the seven filter DoF (rotation vector, translation, time offset).
pub const DOF: [(&str, &str); 7] = [
    ("rx", "deg"),
    ("ry", "deg"),
    ("rz", "deg"),
    ("tx", "mm"),
    ("ty", "mm"),
    ("tz", "mm"),
    ("t_d", "ms"),
];

/// The filter's convergence history in display units (deg, mm, ms).
#[derive(Clone, Debug, Default)]
pub struct History {
    /// Seconds since the first IMU sample.
    pub t: Vec<f64>,
    /// Per DoF of [`DOF`]: the estimate after each update.
    pub value: [Vec<f64>; 7],
    /// Per DoF: its 1-sigma.
    pub sigma: [Vec<f64>; 7],
    /// NIS of each update.
    pub nis: Vec<f64>,
    /// Whether the gate accepted it.
    pub accepted: Vec<bool>,
    /// Its degrees of freedom (0 where the report does not say).
    pub dof: Vec<usize>,
}

impl History {
    /// Reads the `history` array (None when absent or empty).
    pub fn read(report: &Value) -> Option<History> {
        let rows = report.get("history")?.as_array()?;
        if rows.is_empty() {
            return None;
        }
        let mut h = History::default();
        for row in rows {
            let rv: [f64; 3] = nums(row.get("rotation_vector"));
            let tr: [f64; 3] = nums(row.get("translation_m"));
            let sr: [f64; 3] = nums(row.get("sigma_rot_deg"));
            let st: [f64; 3] = nums(row.get("sigma_trans_m"));
            let value = [
                rv[0].to_degrees(),
                rv[1].to_degrees(),
                rv[2].to_degrees(),
                tr[0] * 1e3,
                tr[1] * 1e3,
                tr[2] * 1e3,
                num(row.get("time_offset_s")) * 1e3,
            ];
            let sigma = [
                sr[0],
                sr[1],
                sr[2],
                st[0] * 1e3,
                st[1] * 1e3,
                st[2] * 1e3,
                num(row.get("sigma_time_offset_s")) * 1e3,
            ];
            for i in 0..7 {
                h.value[i].push(value[i]);
                h.sigma[i].push(sigma[i]);
            }
            h.t.push(num(row.get("t_s")));
            h.nis.push(num(row.get("nis")));
            h.accepted
                .push(row.get("accepted").and_then(Value::as_bool) == Some(true));
            h.dof
                .push(row.get("dof").and_then(Value::as_u64).unwrap_or(0) as usize);
        }
        Some(h)
    }
}

/// One row of the result table: DoF name, value, 1-sigma, unit.
pub type ResultRow = (&'static str, f64, f64, &'static str);

/// The final estimate with its 1-sigma per DoF, in display units (empty when the report
/// has none).
pub fn result_rows(report: &Value, history: Option<&History>) -> Vec<ResultRow> {
    if let Some(h) = history {
        return (0..7)
            .map(|i| {
                let last = |v: &Vec<f64>| v.last().copied().unwrap_or(f64::NAN);
                (DOF[i].0, last(&h.value[i]), last(&h.sigma[i]), DOF[i].1)
            })
            .collect();
    }
    let matrix = ["t_cam_lidar", "t_world_cam"]
        .iter()
        .find_map(|key| report.get(*key).filter(|m| m.is_array()));
    let Some(m) = matrix else {
        return Vec::new();
    };
    let rows: [[f64; 4]; 4] = std::array::from_fn(|r| nums(m.get(r)));
    let rotation = Matrix3::from_fn(|r, c| rows[r][c]);
    let rv = Rotation3::from_matrix(&rotation).scaled_axis();
    let sr: [f64; 3] = nums(report.get("sigma_rot_deg"));
    let st: [f64; 3] = nums(report.get("sigma_trans_m"));
    (0..6)
        .map(|i| {
            if i < 3 {
                (DOF[i].0, rv[i].to_degrees(), sr[i], "deg")
            } else {
                (DOF[i].0, rows[i - 3][3] * 1e3, st[i - 3] * 1e3, "mm")
            }
        })
        .collect()
}

/// Degrees of freedom of each history update: the `dof` each history point stores; in
/// reports without it, twice the corners of the image for camera-IMU's corner reprojection
/// (matched by time in `frames`), six for relative poses.
pub fn update_dofs(report: &Value, history: &History) -> Vec<usize> {
    if history.dof.len() == history.t.len() && history.dof.iter().all(|&d| d > 0) {
        return history.dof.clone();
    }
    let reprojection = report.get("update").and_then(Value::as_str) == Some("reprojection");
    let frames: Vec<(f64, usize)> = report
        .get("frames")
        .and_then(Value::as_array)
        .map(|rows| {
            rows.iter()
                .map(|f| {
                    let corners = f.get("corners").and_then(Value::as_u64).unwrap_or(0);
                    (num(f.get("t_s")), corners as usize)
                })
                .collect()
        })
        .unwrap_or_default();
    history
        .t
        .iter()
        .map(|&t| {
            if !reprojection {
                return 6;
            }
            frames
                .iter()
                .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
                .map_or(6, |&(_, corners)| 2 * corners)
        })
        .collect()
}

/// A named series of residuals for a histogram: title, x-axis label, values.
pub type Residuals = (String, String, Vec<f64>);

/// The field `field` of every object of the array `array` (NaN-free).
pub fn column(report: &Value, array: &str, field: &str) -> Vec<f64> {
    report
        .get(array)
        .and_then(Value::as_array)
        .map(|rows| {
            rows.iter()
                .map(|r| num(r.get(field)))
                .filter(|v| v.is_finite())
                .collect()
        })
        .unwrap_or_default()
}

/// The numbers of the array `key` (NaN-free).
pub fn values(report: &Value, key: &str) -> Vec<f64> {
    report
        .get(key)
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .map(|v| num(Some(v)))
                .filter(|v| v.is_finite())
                .collect()
        })
        .unwrap_or_default()
}

/// The residual series each pipeline's report carries.
pub fn residuals(report: &Value, kind: Kind, history: Option<&History>) -> Vec<Residuals> {
    let mut out: Vec<Residuals> = Vec::new();
    let mut push = |title: &str, x: &str, v: Vec<f64>| {
        if !v.is_empty() {
            out.push((title.into(), x.into(), v));
        }
    };
    if let Some(h) = history {
        let dofs = update_dofs(report, h);
        let per_dof = h.nis.iter().zip(&dofs).map(|(n, d)| n / *d as f64);
        push(
            "NIS per DoF of every update",
            "NIS / dof (1 when consistent)",
            per_dof.filter(|v| v.is_finite()).collect(),
        );
    }
    match kind {
        Kind::CameraImu => {
            push(
                "reprojection error after the update",
                "mean error per image, px",
                column(report, "frames", "mean_error_px"),
            );
            push(
                "reprojection error before the update",
                "mean innovation per image, px",
                column(report, "frames", "mean_error_before_px"),
            );
        }
        Kind::LidarImu => push(
            "NDT fitness per scan",
            "mean normalised score per point",
            column(report, "scans", "fitness"),
        ),
        Kind::LidarCamera => {
            push(
                "MLRE per frame",
                "mean line reprojection error, px",
                column(report, "frames", "mlre_px"),
            );
            push(
                "board plane RMS per frame",
                "RMS distance from the camera's board plane, m",
                column(report, "frames", "plane_rms_m"),
            );
        }
        Kind::Infra => {
            push(
                "marker-corner reprojection RMSE per camera",
                "px",
                column(report, "cameras", "reprojection_rmse_px"),
            );
            push(
                "blob reprojection RMSE per camera",
                "px",
                column(report, "cameras", "blob_rmse_px"),
            );
        }
        Kind::PriorMap => {
            push(
                "surveyed points after MI",
                "reprojection error of each surveyed point, px",
                values(report, "survey_px"),
            );
            push(
                "surveyed points at the initialisation",
                "reprojection error of each surveyed point, px",
                values(report, "survey_px_initial"),
            );
        }
        _ => {}
    }
    out
}
