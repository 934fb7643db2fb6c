//! The board planes of the joint calibration: the board's points in each deskewed scan,
//! found where the current estimate puts the board (target frame, LiDAR extrinsic), fitted
//! as a plane with the outliers cut, and fused as a board-plane update.

use std::collections::BTreeMap;

use msreg_estimator::update::board_plane::BoardPlane;
use msreg_estimator::{Ekf, Scalar};
use nalgebra::{Point3, Vector3};
use serde::Serialize;

use super::LIDAR;
use crate::calibrate::convert;
use crate::calibrate::pose_imu::PoseImuError;
use crate::camera_yaml::CheckerboardTarget;
use crate::pointcloud::PointCloud;

/// The filter's static frame of the board.
const TARGET: usize = 0;

/// The physical board in the target frame: centred on the pattern, `width_m` along target x.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardExtent {
    /// Centre of the board in the target frame, m.
    pub centre: Vector3<f64>,
    /// Half width (target x) and half height (target y), m.
    pub half: (f64, f64),
}

impl BoardExtent {
    /// The board of `target.yaml`, which must give its `width_m` and `height_m`.
    pub fn of(target: &CheckerboardTarget) -> Result<Self, PoseImuError> {
        let (Some(w), Some(h)) = (target.width_m, target.height_m) else {
            return Err(PoseImuError::BadInput(
                "target.yaml: the joint calibration needs the board's width_m and height_m \
                 (the physical board, centred on the pattern) to find it in the scans"
                    .into(),
            ));
        };
        let centre = Vector3::new(
            (target.rows.saturating_sub(1)) as f64 * target.row_spacing_m / 2.0,
            (target.cols.saturating_sub(1)) as f64 * target.col_spacing_m / 2.0,
            0.0,
        );
        Ok(Self {
            centre,
            half: (w / 2.0, h / 2.0),
        })
    }
}

/// Board segmentation and the plane update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneOptions {
    /// Points closer than this to the board's edges are left out (returns that straddle an
    /// edge), m.
    pub edge_margin_m: f64,
    /// Fewest board points of a plane.
    pub min_points: usize,
    /// Planes are looked for once the LiDAR extrinsic's largest rotation sigma is below
    /// this, rad (the predicted board then finds the board's points).
    pub arm_sigma_rotation_rad: f64,
    /// ... and its largest translation sigma below this, m.
    pub arm_sigma_translation_m: f64,
    /// Distance from the predicted board plane that a board point may have, m, on top of
    /// 3 sigma of the prediction.
    pub gate_m: f64,
    /// Smallest noise of a point along the board normal, m.
    pub min_sigma_m: f64,
}

impl Default for PlaneOptions {
    fn default() -> Self {
        Self {
            edge_margin_m: 0.04,
            min_points: 50,
            arm_sigma_rotation_rad: 1f64.to_radians(),
            arm_sigma_translation_m: 0.05,
            gate_m: 0.05,
            min_sigma_m: 0.005,
        }
    }
}

/// What became of the scans' board planes.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct PlaneStats {
    /// Planes fused.
    pub fused: usize,
    /// Planes the gate rejected.
    pub rejected: usize,
    /// Scans without a plane, counted by reason.
    pub skipped: BTreeMap<String, usize>,
    /// Mean NIS per dof of the fused and rejected planes.
    pub mean_nis_per_dof: f64,
    /// Mean number of board points per plane.
    pub mean_points: f64,
    /// Mean noise along the normal (the fit's RMS), m.
    pub mean_sigma_m: f64,
}

/// The plane update of every scan.
pub(super) struct PlaneFeed {
    /// Every plane handed to the filter (LiDAR frame at its stamp), for the report.
    pub(super) measurements: Vec<BoardPlane<f64>>,
    board: BoardExtent,
    options: PlaneOptions,
    stats: PlaneStats,
    nis_sum: f64,
    sigma_sum: f64,
    points_sum: usize,
}

impl PlaneFeed {
    pub(super) fn new(board: BoardExtent, options: PlaneOptions) -> Self {
        Self {
            measurements: Vec::new(),
            board,
            options,
            stats: PlaneStats::default(),
            nis_sum: 0.0,
            sigma_sum: 0.0,
            points_sum: 0,
        }
    }

    /// The statistics of the run.
    pub(super) fn stats(&self) -> PlaneStats {
        let n = (self.stats.fused + self.stats.rejected).max(1) as f64;
        PlaneStats {
            mean_nis_per_dof: self.nis_sum / (3.0 * n),
            mean_points: self.points_sum as f64 / n,
            mean_sigma_m: self.sigma_sum / n,
            ..self.stats.clone()
        }
    }

    /// Finds the board in `cloud` (deskewed to its reference stamp `stamp_ns`, LiDAR clock)
    /// and fuses its plane.
    pub(super) fn fuse<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        stamp_ns: u64,
        cloud: &PointCloud,
    ) {
        let plane = match self.plane(ekf, stamp_ns, cloud) {
            Ok(p) => p,
            Err(why) => return self.skip(why),
        };
        match ekf.update_board_plane(LIDAR, TARGET, &plane) {
            Ok(report) => {
                self.measurements.push(BoardPlane {
                    stamp_ns,
                    count: plane.count,
                    centroid: convert::vec3_f64(&plane.centroid),
                    in_plane: plane.in_plane.map(|u| convert::vec3_f64(&u)),
                    spread: plane.spread.map(|x| x.to_f64()),
                    sigma: plane.sigma.to_f64(),
                });
                if report.accepted {
                    self.stats.fused += 1;
                } else {
                    self.stats.rejected += 1;
                }
                self.nis_sum += report.nis.to_f64();
                self.sigma_sum += plane.sigma.to_f64();
                self.points_sum += plane.count as usize;
            }
            Err(e) => self.skip(format!("update failed: {e}")),
        }
    }

    fn skip(&mut self, why: impl Into<String>) {
        *self.stats.skipped.entry(why.into()).or_default() += 1;
    }

    /// The board plane of one scan at the current estimate.
    fn plane<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
        stamp_ns: u64,
        cloud: &PointCloud,
    ) -> Result<BoardPlane<T>, String> {
        let target = ekf.frame(TARGET).ok_or("no target yet")?;
        let (sr, st) = ekf.extrinsic_sigma(LIDAR);
        let (sr, st) = (sr.amax().to_f64(), st.amax().to_f64());
        if sr > self.options.arm_sigma_rotation_rad || st > self.options.arm_sigma_translation_m {
            return Err("LiDAR extrinsic not yet known well enough to find the board".into());
        }
        let t = ekf
            .imu_time(LIDAR, stamp_ns)
            .map_err(|e| e.to_string())?
            .max(ekf.time_ns());
        let imu = ekf.predict_imu(t).map_err(|e| e.to_string())?.pose();
        let t_t_l = convert::isometry(&target).inverse()
            * convert::isometry(&imu)
            * convert::isometry(&ekf.extrinsic(LIDAR));
        let range = (t_t_l.inverse() * Point3::from(self.board.centre))
            .coords
            .norm();
        let gate = self.options.gate_m + 3.0 * (st + sr * range);
        let candidates = self.on_board(cloud, &t_t_l, gate);
        let plane = self.fit(&candidates)?;
        Ok(BoardPlane {
            stamp_ns,
            count: plane.count,
            centroid: convert::vec3(&plane.centroid),
            in_plane: plane.in_plane.map(|u| convert::vec3(&u)),
            spread: plane.spread.map(T::lit),
            sigma: T::lit(plane.sigma),
        })
    }

    /// The points of `cloud` within `gate` of the predicted board plane and inside the
    /// board (less the edge margin).
    fn on_board(
        &self,
        cloud: &PointCloud,
        t_t_l: &nalgebra::Isometry3<f64>,
        gate: f64,
    ) -> Vec<Vector3<f64>> {
        let (hx, hy) = (
            self.board.half.0 - self.options.edge_margin_m,
            self.board.half.1 - self.options.edge_margin_m,
        );
        cloud
            .points
            .iter()
            .filter(|p| {
                let q = (t_t_l * Point3::from(p.xyz)).coords - self.board.centre;
                q.z.abs() < gate && q.x.abs() < hx && q.y.abs() < hy
            })
            .map(|p| p.xyz)
            .collect()
    }

    /// A plane through `points` with the points beyond 3 sigma of a first fit cut, its
    /// noise the refit's RMS (floored).
    fn fit(&self, points: &[Vector3<f64>]) -> Result<BoardPlane<f64>, String> {
        let too_few = || format!("fewer than {} board points", self.options.min_points);
        let floor = self.options.min_sigma_m;
        if points.len() < self.options.min_points {
            return Err(too_few());
        }
        let first = BoardPlane::from_points(0, points, floor).map_err(|e| e.to_string())?;
        let (normal, rms) = (first.normal(), first.distance_rms(points).unwrap_or(0.0));
        let cut = 3.0 * rms.max(floor);
        let kept: Vec<Vector3<f64>> = points
            .iter()
            .filter(|p| (*p - first.centroid).dot(&normal).abs() < cut)
            .copied()
            .collect();
        if kept.len() < self.options.min_points {
            return Err(too_few());
        }
        let mut plane = BoardPlane::from_points(0, &kept, floor).map_err(|e| e.to_string())?;
        plane.sigma = plane.distance_rms(&kept).unwrap_or(0.0).max(floor);
        Ok(plane)
    }
}
