//! The board planes of the joint calibration: the board's points in each deskewed scan,
//! found where the current estimate puts the board (target frame, LiDAR extrinsic), fitted
//! as a plane with the outliers cut, and fused as a board-plane update.

use std::collections::BTreeMap;

use msreg_estimator::update::board_plane::BoardPlane;
use msreg_estimator::{Ekf, Scalar, TARGET_FRAME};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use serde::Serialize;

use super::LIDAR;
use crate::calibrate::convert;
use crate::calibrate::InputError;
use crate::camera_yaml::CheckerboardTarget;
use crate::lidar::deskew::DeskewedScan;
use crate::pointcloud::ray_plane::fit_ray_plane;

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
    pub fn of(target: &CheckerboardTarget) -> Result<Self, InputError> {
        let (Some(w), Some(h)) = (target.width_m, target.height_m) else {
            return Err(InputError::BoardSizeMissing);
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
    /// Smallest range noise of a board return, m.
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
    /// The board returns (in L at the scan stamp) of the last plane handed to the filter.
    pub(super) last_returns: Vec<Vector3<f64>>,
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
            last_returns: Vec::new(),
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

    /// Finds the board in `scan` (deskewed to its reference stamp `stamp_ns`, LiDAR clock)
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
        scan: &DeskewedScan,
    ) {
        let (plane, returns) = match self.plane(ekf, stamp_ns, scan) {
            Ok(p) => p,
            Err(why) => return self.skip(why),
        };
        match ekf.update_board_plane(LIDAR, TARGET_FRAME, &plane) {
            Ok(report) => {
                self.last_returns = returns;
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

    /// The board plane of one scan at the current estimate, and the returns it came from.
    fn plane<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
        stamp_ns: u64,
        scan: &DeskewedScan,
    ) -> Result<(BoardPlane<T>, Vec<Vector3<f64>>), String> {
        let target = ekf.frame(TARGET_FRAME).ok_or("no target yet")?;
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
        let candidates = self.on_board(scan, &t_t_l, gate);
        let plane = self.fit(&candidates)?;
        let returns = candidates.into_iter().map(|(_, x)| x).collect();
        let moments = BoardPlane {
            stamp_ns,
            count: plane.count,
            centroid: convert::vec3(&plane.centroid),
            in_plane: plane.in_plane.map(|u| convert::vec3(&u)),
            spread: plane.spread.map(T::lit),
            sigma: T::lit(plane.sigma),
        };
        Ok((moments, returns))
    }

    /// The returns of `scan` (`(ray origin, point)`) within `gate` of the predicted board
    /// plane whose rays cross the board (less the edge margin).
    ///
    /// The test is on the ray, not on the point: range noise moves a point along its ray,
    /// so sideways too on a board seen at an angle. A fixed rectangle tested on the points
    /// would lose the points pushed out of it, far ones on one side and near ones on the
    /// other; where the rays spread out from the sensor (any oblique or frontal view), more
    /// far ones leave than near ones enter, and the plane fitted to what remains sits
    /// towards the sensor: +0.2 mm at the truth with 2 cm range noise, more with a wider
    /// margin (docs/joint.md). Where a ray crosses the board does not depend on its range.
    fn on_board(
        &self,
        scan: &DeskewedScan,
        t_t_l: &nalgebra::Isometry3<f64>,
        gate: f64,
    ) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        let (hx, hy) = (
            self.board.half.0 - self.options.edge_margin_m,
            self.board.half.1 - self.options.edge_margin_m,
        );
        let in_board = |p: &Point3<f64>| p.coords - self.board.centre;
        scan.cloud
            .points
            .iter()
            .filter(|p| {
                let q = in_board(&(t_t_l * Point3::from(p.xyz)));
                let o = in_board(&(t_t_l * Point3::from(scan.ray_origin(p.t_ns))));
                let ray = q - o;
                if q.z.abs() >= gate || ray.z.abs() < 1e-9 {
                    return false;
                }
                let crossing = o - ray * (o.z / ray.z);
                crossing.x.abs() < hx && crossing.y.abs() < hy
            })
            .map(|p| (scan.ray_origin(p.t_ns), p.xyz))
            .collect()
    }

    /// The board's plane along the rays of `returns` (`(ray origin, point)`), the returns
    /// beyond 3 range sigmas of a first fit cut ([`fit_ray_plane`]), as the moments the
    /// filter's plane update takes.
    fn fit(&self, returns: &[(Vector3<f64>, Vector3<f64>)]) -> Result<BoardPlane<f64>, String> {
        let (origins, points): (Vec<_>, Vec<_>) = returns.iter().copied().unzip();
        let plane = fit_ray_plane(&origins, &points, 3.0, self.options.min_points)
            .map_err(|e| e.to_string())?;
        let sigma = plane.range_sigma.max(self.options.min_sigma_m);
        weighted_moments(&plane.on_plane, &plane.inverse_cos2, sigma)
            .ok_or_else(|| "the board's returns do not span a plane".to_string())
    }
}

/// The board-plane moments of points on the fitted plane with per-point information
/// `w_k / sigma^2` (`w_k = 1 / cos^2` of the ray's incidence: a range noise `sigma` is
/// `sigma cos` along the normal).
///
/// [`BoardPlane`] whitens its rows with one `sigma` and the count `K`: the distance row
/// carries `K / sigma_eff^2`, a tilt row `lambda_i / sigma_eff^2`. With `W = sum w_k`, the
/// weighted centroid and scatter (eigenvalues `L_i`) give the same information with
/// `sigma_eff = sigma sqrt(K / W)` and `lambda_i = L_i K / W`.
fn weighted_moments(
    points: &[Vector3<f64>],
    weights: &[f64],
    sigma: f64,
) -> Option<BoardPlane<f64>> {
    let total: f64 = weights.iter().sum();
    let count = u32::try_from(points.len()).ok()?;
    if points.len() != weights.len() || total <= 0.0 || count < 3 {
        return None;
    }
    let centroid = points
        .iter()
        .zip(weights)
        .map(|(x, w)| x * *w)
        .sum::<Vector3<f64>>()
        / total;
    let scatter = points
        .iter()
        .zip(weights)
        .fold(Matrix3::zeros(), |m, (x, w)| {
            let d = x - centroid;
            m + d * d.transpose() * *w
        });
    let eigen = SymmetricEigen::new(scatter);
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let scale = f64::from(count) / total;
    let plane = BoardPlane {
        stamp_ns: 0,
        count,
        centroid,
        in_plane: [0, 1].map(|i| eigen.eigenvectors.column(order[i]).into_owned()),
        spread: [0, 1].map(|i| eigen.eigenvalues[order[i]] * scale),
        sigma: sigma * scale.sqrt(),
    };
    plane.validate().ok().map(|()| plane)
}
