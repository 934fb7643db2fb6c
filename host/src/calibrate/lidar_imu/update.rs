//! One scan's step of the LiDAR feed: deskew, NDT against the previous scan, the
//! measurement noise (and its adaptation), the gated relative-pose update.

use super::feed::*;
use super::*;
use crate::calibrate::convert;
use crate::lidar::deskew::{imu_time, DeskewedScan};
use crate::lidar::deskew_scan;
use crate::ndt::{align, NdtError, NdtResult, NdtTarget};
use crate::pointcloud::voxel_downsample;
use msreg_estimator::{Ekf, Error as FilterError, RelativePose, Scalar};
use nalgebra::{Isometry3, Matrix6, Vector3, Vector6};
use std::time::Instant;

/// What one scan's step carries from stage to stage.
struct ScanStep {
    /// The scan's row of the report, filled in as the step goes.
    record: ScanRecord,
    /// Reference stamp, LiDAR clock.
    ref_stamp: u64,
    /// IMU time of the reference stamp.
    due: u64,
    /// The filter's time offset of the LiDAR, ns.
    td_ns: i64,
    /// The filter's IMU pose at `due`, before the update.
    predicted: Isometry3<f64>,
    /// The filter's `T_imu_lidar`.
    t_i_l: Isometry3<f64>,
}

impl<'a> LidarFeed<'a> {
    /// Predict -> deskew -> NDT -> update for one scan whose reference time has come.
    pub(crate) fn process<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        p: Pending,
    ) {
        let mut step = self.predict_scan(ekf, &p);
        let (mut this, points) = match self.deskewed_target(&mut step, p) {
            Ok(prepared) => prepared,
            Err(why) => {
                self.reject(ekf, step.record, step.ref_stamp, &why);
                return;
            }
        };
        let Some(prev) = self.previous.take() else {
            self.start_chain(ekf, step.record, this, "anchor");
            return;
        };
        let guess = match self.buffer.at(prev.imu_time_ns) {
            Some(t_g_prev) => {
                step.t_i_l.inverse() * t_g_prev.inverse() * step.predicted * step.t_i_l
            }
            None => Isometry3::identity(),
        };
        let matched = self.register(&prev, &mut this, &points, &guess);
        let result = match self.accepted_match(matched, &mut step.record) {
            Ok(result) => result,
            Err(why) => {
                self.start_chain(ekf, step.record, this, &why);
                return;
            }
        };
        let (meas, ndt_share) =
            self.relative_pose_measurement(ekf, &mut step, &prev, &result, &guess);
        self.apply_update(ekf, step, this, &meas, ndt_share);
    }

    /// Predicts the filter to the scan's reference time (the pose also goes to the deskew
    /// buffer) and starts its record.
    fn predict_scan<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        p: &Pending,
    ) -> ScanStep {
        let td_ns = (ekf.time_offset(self.sensor).to_f64() * 1e9).round() as i64;
        let ref_stamp = p.stamp_ns.saturating_add(p.ref_offset_ns);
        let due = imu_time(p.stamp_ns, p.ref_offset_ns, td_ns);
        // Predict: the filter's pose at `due`, over the same interpolated IMU readings the
        // filter will propagate with (the scan is due, so `due` is within reach).
        let predicted = match ekf.predict_imu(due.max(ekf.time_ns())) {
            Ok(state) => convert::isometry(&state.pose()),
            Err(_) => convert::isometry(&ekf.imu().pose()),
        };
        self.buffer.push(due, predicted);
        let t_i_l = convert::isometry(&ekf.extrinsic(self.sensor));
        let t_s = due.saturating_sub(self.first_imu_ns) as f64 * 1e-9;
        ScanStep {
            record: ScanRecord::unmatched(p.stamp_ns, ref_stamp, t_s, p.cloud.len(), String::new()),
            ref_stamp,
            due,
            td_ns,
            predicted,
            t_i_l,
        }
    }

    /// Deskews, voxel-filters and builds the NDT target of the scan: the next match's
    /// `Previous` and the filtered points, or why the scan is rejected.
    fn deskewed_target(
        &mut self,
        step: &mut ScanStep,
        p: Pending,
    ) -> Result<(Previous, Vec<Vector3<f64>>), String> {
        let started = Instant::now();
        let deskewed = if self.options.deskew {
            deskew_scan(
                &p.cloud,
                p.stamp_ns,
                p.ref_offset_ns,
                step.td_ns,
                &step.t_i_l,
                &self.buffer,
            )
        } else {
            Some(DeskewedScan::undistorted(p.cloud))
        };
        self.timing.deskew += started.elapsed().as_secs_f64();
        let deskewed = deskewed.ok_or("no IMU poses to deskew with")?;
        let started = Instant::now();
        let filtered = voxel_downsample(&deskewed.cloud, self.options.voxel_m);
        if self.keep_deskewed {
            self.deskewed = Some((step.ref_stamp, deskewed));
        }
        let points = filtered.positions();
        step.record.points_filtered = points.len();
        let target = NdtTarget::build(&points, &self.options.ndt);
        self.timing.voxel_and_target += started.elapsed().as_secs_f64();
        if points.len() < self.options.min_points {
            return Err("too few points after voxel filtering".into());
        }
        let target = target.map_err(|e| format!("no NDT target: {e}"))?;
        let this = Previous {
            ref_stamp_ns: step.ref_stamp,
            imu_time_ns: step.due,
            target,
            cloud: self.map.is_some().then_some(filtered),
            t_map: Isometry3::identity(),
        };
        Ok((this, points))
    }

    /// NDT of the scan against the previous one (or the local map) from `guess`: the
    /// increment `T_prev_this` with its covariance; `this.t_map` becomes its map pose.
    fn register(
        &mut self,
        prev: &Previous,
        this: &mut Previous,
        points: &[Vector3<f64>],
        guess: &Isometry3<f64>,
    ) -> Result<NdtResult, NdtError> {
        let started = Instant::now();
        let matched = match (&mut self.map, &this.cloud) {
            (Some(map), Some(cloud)) => map.align(cloud, &(prev.t_map * guess)).map(|mut r| {
                // T_prev_this = T_map_prev^-1 T_map_this; the covariance of `[t; theta]`
                // moves with it: translation rotated into the previous scan's frame,
                // rotation (a right perturbation of this scan's pose) unchanged.
                this.t_map = r.t_target_source;
                r.t_target_source = prev.t_map.inverse() * r.t_target_source;
                let mut j = Matrix6::identity();
                j.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(prev.t_map.rotation.inverse().to_rotation_matrix().matrix());
                r.covariance = j * r.covariance * j.transpose();
                for c in [&mut r.covariance_sandwich, &mut r.covariance_clustered] {
                    *c = c.map(|c| j * c * j.transpose());
                }
                r
            }),
            _ => align(&prev.target, points, guess, &self.options.ndt),
        };
        self.timing.ndt += started.elapsed().as_secs_f64();
        matched
    }

    /// The match if it converged with enough fitness, else why not (the odometry chain
    /// restarts at this scan); fitness and iterations go to the record either way.
    fn accepted_match(
        &self,
        matched: Result<NdtResult, NdtError>,
        record: &mut ScanRecord,
    ) -> Result<NdtResult, String> {
        let r = matched.map_err(|e| format!("NDT failed: {e}"))?;
        record.fitness = Some(r.fitness);
        record.iterations = Some(r.iterations);
        if r.converged && r.fitness >= self.options.min_fitness {
            return Ok(r);
        }
        Err(if let Some(d) = &r.degenerate {
            format!("degenerate NDT match ({d:?})")
        } else if !r.converged {
            "NDT did not converge".to_string()
        } else {
            format!(
                "NDT fitness {:.3} below {}",
                r.fitness, self.options.min_fitness
            )
        })
    }

    /// The relative-pose measurement of the match (its noise from the NDT covariance, the
    /// floor and the adaptation), booked in the record and the innovation statistics; also
    /// the NDT term's share of `R`.
    fn relative_pose_measurement<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
        step: &mut ScanStep,
        prev: &Previous,
        result: &NdtResult,
        guess: &Isometry3<f64>,
    ) -> (RelativePose<T>, f64) {
        let sigma_ratio = extrinsic_sigma_ratio(ekf, self.sensor).max(self.imu_sigma_ratio(ekf));
        let (covariance, ndt_share) = self.measurement_covariance(
            match self.options.ndt_covariance {
                NdtCovariance::Hessian => &result.covariance,
                // `calibrate` checked that `ndt.sandwich_covariance` computes these.
                NdtCovariance::Sandwich => result
                    .covariance_sandwich
                    .as_ref()
                    .unwrap_or(&result.covariance),
                NdtCovariance::Clustered => result
                    .covariance_clustered
                    .as_ref()
                    .unwrap_or(&result.covariance),
            },
            sigma_ratio,
        );
        self.updates += 1;
        let delta = result.t_target_source;
        self.book_innovation(guess, &delta, &covariance);
        let record = &mut step.record;
        let rv = delta.rotation.scaled_axis();
        record.delta_rotation = Some([rv.x, rv.y, rv.z]);
        record.delta_translation = Some(delta.translation.vector.into());
        record.sigma = Some(std::array::from_fn(|i| covariance[(i, i)].sqrt()));
        record.ndt = Some(result.clone());
        record.predicted = Some(*guess);
        let meas = RelativePose {
            stamp_from_ns: prev.ref_stamp_ns,
            stamp_to_ns: step.ref_stamp,
            delta: convert::pose::<T>(&delta),
            covariance: Matrix6::from_fn(|r, c| T::lit(covariance[(r, c)])),
        };
        (meas, ndt_share)
    }

    /// The filter update with the measurement; on success the scan becomes the next match's
    /// previous one (and joins the local map).
    fn apply_update<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        step: ScanStep,
        this: Previous,
        meas: &RelativePose<T>,
        ndt_share: f64,
    ) {
        let ScanStep {
            mut record,
            ref_stamp,
            predicted,
            ..
        } = step;
        match ekf.update_relative_pose(self.sensor, meas) {
            Ok(report) => {
                // The update moved the current pose: keep the buffer continuous.
                let after = convert::isometry(&ekf.imu().pose());
                self.buffer.reanchor(&(after * predicted.inverse()));
                self.buffer.push(ekf.time_ns(), after);
                self.run.record_update(ekf, ref_stamp, &report);
                record.nis = Some(report.nis.to_f64());
                self.adapt(report.nis.to_f64() / report.dof.max(1) as f64, ndt_share);
                record.status = if report.accepted {
                    "matched".into()
                } else {
                    "rejected by the gate".into()
                };
                self.last_end_ns = Some(ref_stamp);
                if let (Some(map), Some(cloud)) = (&mut self.map, &this.cloud) {
                    map.insert(cloud, &this.t_map);
                }
                self.previous = Some(this);
                self.records.push(record);
            }
            Err(FilterError::NoAnchor | FilterError::OlderThanWindow) => {
                self.start_chain(ekf, record, this, "filter lost the anchor; restarted");
            }
            Err(e) => {
                self.reject(ekf, record, ref_stamp, &format!("update failed: {e}"));
            }
        }
    }

    /// Books one update's NIS/dof (and the NDT term's share of `R`) and, when due, adjusts
    /// the noise scale ([`NoiseAdaptation`]).
    pub(crate) fn adapt(&mut self, nis_per_dof: f64, ndt_share: f64) {
        let Some(a) = self.options.adapt else {
            return;
        };
        self.nis_per_dof.push((nis_per_dof.min(a.clip), ndt_share));
        let start = (a.start_after_anneals * self.options.anneal_updates).ceil() as usize;
        let n = self.nis_per_dof.len();
        if n < start + a.window.min(a.every) || n % a.every.max(1) != 0 {
            return;
        }
        let recent = &self.nis_per_dof[n - a.window.min(n - start)..];
        let count = recent.len().max(1) as f64;
        let mean = recent.iter().map(|(x, _)| x).sum::<f64>() / count;
        let share = recent.iter().map(|(_, w)| w).sum::<f64>() / count;
        if !mean.is_finite() || mean <= 0.0 || !share.is_finite() {
            return;
        }
        // Only the NDT term's share of the mismatch is the scale's to correct: while the
        // floor dominates `R`, the NIS says little about the scale.
        // With the NDT term inflated by `inflation` for correlated errors, a consistent
        // NIS/dof is about 1/inflation.
        let step = (mean * self.inflation)
            .powf(0.5 * share.clamp(0.0, 1.0))
            .clamp(1.0 / a.max_step, a.max_step);
        let base = self.options.covariance_scale[0].max(f64::MIN_POSITIVE);
        let scale = (base * self.adaptive_factor * step).clamp(a.bounds[0], a.bounds[1]);
        self.adaptive_factor = scale / base;
        if a.correlation_window > 0 {
            let pairs = &self.innovation_pairs[self
                .innovation_pairs
                .len()
                .saturating_sub(a.correlation_window)..];
            let (num, den) = pairs
                .iter()
                .fold((0.0, 0.0), |(n, d), (x, y)| (n + x, d + y));
            if pairs.len() * 2 >= a.correlation_window && den > 0.0 {
                let rho = (num / den).clamp(0.0, 0.95);
                self.inflation = ((1.0 + rho) / (1.0 - rho)).min(a.max_inflation);
            }
        }
    }

    /// Books the innovation `delta (-) guess` (the filter's prediction of the increment),
    /// normalised by `sqrt(R_ii)`, for the lag-1 autocorrelation of consecutive ones.
    pub(crate) fn book_innovation(
        &mut self,
        guess: &Isometry3<f64>,
        delta: &Isometry3<f64>,
        covariance: &Matrix6<f64>,
    ) {
        let r = (guess.rotation.inverse() * delta.rotation).scaled_axis();
        let t = delta.translation.vector - guess.translation.vector;
        let nu = Vector6::new(r.x, r.y, r.z, t.x, t.y, t.z);
        let u = Vector6::from_fn(|i, _| nu[i] / covariance[(i, i)].max(f64::MIN_POSITIVE).sqrt());
        if let Some(p) = self.last_innovation {
            self.innovation_pairs
                .push((u.dot(&p), 0.5 * (u.norm_squared() + p.norm_squared())));
        }
        self.last_innovation = Some(u);
    }

    /// `R = scale * Sigma_NDT + floor`, reordered from NDT's `[t; theta]` to the filter's
    /// `[theta; t]` (both: rotation a right perturbation, translation additive in the
    /// target = `from` frame).
    ///
    /// Also returns the NDT term's mean share of the diagonal of `R` (the adaptation's weight).
    ///
    /// The floor's excess over its final value decays with the update count and, with
    /// `anneal_by_sigma`, at least as fast as `sigma_ratio` (the filter's largest extrinsic
    /// sigma relative to its prior).
    pub(crate) fn measurement_covariance(
        &self,
        ndt: &Matrix6<f64>,
        sigma_ratio: f64,
    ) -> (Matrix6<f64>, f64) {
        let o = self.options;
        let mut decay = if o.anneal_updates > 0.0 {
            (-(self.updates as f64) / o.anneal_updates).exp()
        } else {
            0.0
        };
        if o.anneal_by_sigma && sigma_ratio.is_finite() {
            decay = decay.min(sigma_ratio.clamp(0.0, 1.0));
        }
        let floor = |initial: f64, last: f64| last + (initial - last).max(0.0) * decay;
        let floor_r = floor(o.initial_rotation_floor_rad, o.rotation_floor_rad);
        let floor_t = floor(o.initial_translation_floor_m, o.translation_floor_m);
        // S Sigma S with S = diag(sqrt(s_rot) I, sqrt(s_trans) I) keeps `c` positive definite.
        let s = |i: usize| {
            (o.covariance_scale[usize::from(i >= 3)] * self.adaptive_factor * self.inflation)
                .max(0.0)
                .sqrt()
        };
        let mut c = Matrix6::from_fn(|r, col| ndt[((r + 3) % 6, (col + 3) % 6)] * s(r) * s(col));
        let ndt_diagonal = c.diagonal();
        for i in 0..3 {
            c[(i, i)] += floor_r.powi(2);
            c[(i + 3, i + 3)] += floor_t.powi(2);
        }
        let share = (0..6)
            .map(|i| ndt_diagonal[i] / c[(i, i)].max(f64::MIN_POSITIVE))
            .sum::<f64>()
            / 6.0;
        ((c + c.transpose()) * 0.5, share)
    }

    /// Starts a new odometry chain at this scan (first scan, or after a failed match).
    pub(crate) fn start_chain<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        mut record: ScanRecord,
        mut this: Previous,
        why: &str,
    ) {
        match ekf.anchor(self.sensor, this.ref_stamp_ns) {
            Ok(()) => {
                // A new chain: the local map restarts in this scan's frame.
                this.t_map = Isometry3::identity();
                self.last_innovation = None;
                if let (Some(map), Some(cloud)) = (&mut self.map, &this.cloud) {
                    map.clear();
                    map.insert(cloud, &this.t_map);
                }
                if why != "anchor" {
                    self.run.skipped.push(format!(
                        "lidar0 scan {}: {why}; odometry restarted here",
                        record.stamp_ns
                    ));
                }
                record.status = why.to_string();
                self.last_end_ns = Some(this.ref_stamp_ns);
                self.previous = Some(this);
                self.records.push(record);
            }
            Err(e) => {
                let stamp = this.ref_stamp_ns;
                self.reject(ekf, record, stamp, &format!("cannot anchor: {e}"));
            }
        }
    }

    /// Skips a processed scan and breaks the odometry chain.
    pub(crate) fn reject<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        _ekf: &mut Ekf<T, S, C, N, F>,
        mut record: ScanRecord,
        ref_stamp: u64,
        why: &str,
    ) {
        self.run
            .skipped
            .push(format!("lidar0 scan {}: {why}", record.stamp_ns));
        record.status = why.to_string();
        self.previous = None;
        self.last_innovation = None;
        self.last_end_ns = Some(ref_stamp);
        self.records.push(record);
    }
}
