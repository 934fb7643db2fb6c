//! The LiDAR's measurement feed of the IMU driver: scans deskewed with the filter's poses,
//! registered by NDT to the previous one, fused as relative poses when due
//! ([`update`](super::update): the registration and the update).

use super::*;
use crate::calibrate::convert;
use crate::calibrate::driver::verdict::Run;
use crate::calibrate::driver::ImuHooks;
use crate::calibrate::InputError;
use crate::dataset::ImuRecord;
use crate::lidar::deskew::DeskewedScan;
use crate::lidar::{PoseBuffer, ScanSource};
use crate::ndt::{LocalMap, NdtTarget};
use crate::pointcloud::PointCloud;
use msreg_estimator::{Ekf, Scalar, SensorId};
use nalgebra::{Isometry3, Vector6};
use std::time::Instant;

/// A scan read and waiting for the IMU to reach its reference time.
pub(crate) struct Pending {
    pub(crate) index: usize,
    pub(crate) stamp_ns: u64,
    pub(crate) ref_offset_ns: u64,
    pub(crate) cloud: PointCloud,
}

/// The last deskewed scan: the target of the next match.
pub(crate) struct Previous {
    /// Reference stamp, LiDAR clock (the filter's anchor stamp).
    pub(crate) ref_stamp_ns: u64,
    /// Its IMU time when it was processed.
    pub(crate) imu_time_ns: u64,
    pub(crate) target: NdtTarget,
    /// The voxel-filtered deskewed scan (scan-to-local-map only).
    pub(crate) cloud: Option<PointCloud>,
    /// Its pose in the local map's frame (identity at a chain's anchor).
    pub(crate) t_map: Isometry3<f64>,
}

/// The LiDAR front-end of the filter loop.
pub(crate) struct LidarFeed<'a> {
    /// The filter's LiDAR.
    pub(crate) sensor: SensorId,
    /// Keep every deskewed scan for [`LidarFeed::take_deskewed`] (the joint calibration's
    /// board planes).
    pub(crate) keep_deskewed: bool,
    pub(crate) deskewed: Option<(u64, DeskewedScan)>,
    pub(crate) run: Run,
    pub(crate) scans: &'a dyn ScanSource,
    pub(crate) options: &'a LidarImuOptions,
    pub(crate) next: usize,
    pub(crate) pending: Option<Pending>,
    pub(crate) previous: Option<Previous>,
    pub(crate) last_end_ns: Option<u64>,
    pub(crate) buffer: PoseBuffer,
    pub(crate) records: Vec<ScanRecord>,
    pub(crate) timing: StageTiming,
    pub(crate) first_imu_ns: u64,
    /// Relative poses formed so far (drives the floor's annealing).
    pub(crate) updates: usize,
    /// Factor on `covariance_scale` from the NIS adaptation (1 until it starts).
    pub(crate) adaptive_factor: f64,
    /// NIS/dof of the updates and the NDT term's share of their `R`, in order (adaptation).
    pub(crate) nis_per_dof: Vec<(f64, f64)>,
    /// Scan-to-local-map target (`local_map_scans > 0`), in the frame of the chain's anchor.
    pub(crate) map: Option<LocalMap>,
    /// The previous update's innovation, normalised per component by `sqrt(R_ii)` (within
    /// an odometry chain).
    pub(crate) last_innovation: Option<Vector6<f64>>,
    /// Per consecutive pair of innovations: `(sum u_k u_k-1, sum (u_k^2 + u_k-1^2) / 2)`.
    pub(crate) innovation_pairs: Vec<(f64, f64)>,
    /// Inflation of the NDT term for time-correlated errors, `(1 + rho) / (1 - rho)`.
    pub(crate) inflation: f64,
    /// Anneal the floor by the IMU velocity's sigma too (a moving start, see
    /// [`LidarFeed::annealed_by_imu_state`]): `None` off, `Some(None)` on and the sigma at
    /// the first scan not yet read, `Some(Some(sigma))` on.
    pub(crate) imu_anneal: Option<Option<f64>>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    ImuHooks<T, Ekf<T, S, C, N, F>> for LidarFeed<'_>
{
    fn fuse_due(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        while self.next_due(ekf)?.is_some() {
            self.fuse_next(ekf, index);
        }
        Ok(())
    }

    fn after_sample(&mut self, ekf: &Ekf<T, S, C, N, F>, _rec: &ImuRecord) {
        self.buffer
            .push(ekf.time_ns(), convert::isometry(&ekf.imu().pose()));
    }
}

impl<'a> LidarFeed<'a> {
    /// The feed of sensor `sensor` of the filter; `keep_deskewed` keeps each deskewed scan
    /// for [`LidarFeed::take_deskewed`].
    pub(crate) fn new(
        scans: &'a dyn ScanSource,
        options: &'a LidarImuOptions,
        first_imu_ns: u64,
        (sensor, keep_deskewed): (SensorId, bool),
    ) -> Self {
        Self {
            sensor,
            keep_deskewed,
            deskewed: None,
            run: Run::new(first_imu_ns, 100_000_000).for_sensor(sensor),
            scans,
            options,
            next: 0,
            pending: None,
            previous: None,
            last_end_ns: None,
            buffer: PoseBuffer::new(2_000_000_000),
            records: Vec::new(),
            timing: StageTiming::default(),
            first_imu_ns,
            updates: 0,
            adaptive_factor: 1.0,
            nis_per_dof: Vec::new(),
            last_innovation: None,
            innovation_pairs: Vec::new(),
            inflation: 1.0,
            imu_anneal: None,
            map: (options.local_map_scans > 0)
                .then(|| {
                    LocalMap::new(
                        options.local_map_scans,
                        options.voxel_m,
                        options.ndt.clone(),
                    )
                })
                .and_then(Result::ok),
        }
    }

    /// Also anneals the floor by the IMU velocity's sigma relative to its value at the
    /// first scan: the floor's excess then shrinks no faster than the larger of the
    /// extrinsic's and the velocity's sigma ratios. For a moving start, whose IMU state comes
    /// from the dynamic alignment with a wide velocity sigma (0.1 m/s): at peak motion the
    /// extrinsic sigma falls to a few per cent of its prior within a second, while the
    /// velocity, with which the scans are deskewed and the increments predicted, is still
    /// settling; the floor stands for that error until the filter has settled it
    /// (docs/lidar_imu.md, "Moving start: the floor and the IMU state").
    pub(crate) fn annealed_by_imu_state(mut self) -> Self {
        self.imu_anneal = Some(None);
        self
    }

    /// The velocity sigma ratio of [`LidarFeed::annealed_by_imu_state`] (0 when off).
    pub(crate) fn imu_sigma_ratio<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> f64 {
        let Some(stored) = self.imu_anneal else {
            return 0.0;
        };
        let now = velocity_sigma(ekf);
        let first = stored.unwrap_or(now);
        self.imu_anneal = Some(Some(first));
        if first > 0.0 {
            now / first
        } else {
            0.0
        }
    }

    /// Reads the next scan once its stamp is due and returns its reference stamp (LiDAR
    /// clock) when that is due too: the scan can be processed now ([`LidarFeed::fuse_next`]).
    pub(crate) fn next_due<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> Result<Option<u64>, InputError> {
        loop {
            if let Some(p) = self.pending.as_ref() {
                let reference = p.stamp_ns.saturating_add(p.ref_offset_ns);
                return Ok(ekf.is_due(self.sensor, reference).then_some(reference));
            }
            if self.next >= self.scans.len() {
                return Ok(None);
            }
            let k = self.next;
            let stamp = self.scans.stamp_ns(k);
            if !ekf.is_due(self.sensor, stamp) {
                return Ok(None);
            }
            self.next += 1;
            let started = Instant::now();
            let cloud = load(self.scans, k);
            self.timing.load += started.elapsed().as_secs_f64();
            let Some(cloud) = cloud? else {
                self.skip(k, stamp, "zero points");
                continue;
            };
            let last = last_firing_ns(&cloud);
            let ref_offset_ns = if self.options.deskew { last } else { last / 2 };
            let ref_stamp = stamp.saturating_add(ref_offset_ns);
            if self.last_end_ns.is_some_and(|e| ref_stamp <= e) {
                self.skip(
                    k,
                    stamp,
                    "stamp not after the previous scan's (out of order)",
                );
                continue;
            }
            self.pending = Some(Pending {
                index: k,
                stamp_ns: stamp,
                ref_offset_ns,
                cloud,
            });
        }
    }

    /// Processes the scan [`LidarFeed::next_due`] found due (`index`: the IMU sample fed
    /// last).
    pub(crate) fn fuse_next<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
    ) {
        let Some(p) = self.pending.take() else {
            return;
        };
        if index > 0 {
            self.process(ekf, p);
        } else {
            self.skip(p.index, p.stamp_ns, "before the first IMU sample");
        }
    }

    /// Another sensor's update moved the filter's pose at `time_ns` from `before` to
    /// `after`: the buffered poses move with it, so that deskewing sees one continuous
    /// motion (as after the LiDAR's own updates).
    pub(crate) fn filter_corrected(
        &mut self,
        time_ns: u64,
        before: &Isometry3<f64>,
        after: &Isometry3<f64>,
    ) {
        self.buffer.reanchor(&(after * before.inverse()));
        self.buffer.push(time_ns, *after);
    }

    /// Books every scan not reached (pending or unread) as after the last IMU sample.
    pub(crate) fn skip_remaining(&mut self) {
        if let Some(p) = self.pending.take() {
            self.skip(p.index, p.stamp_ns, "after the last IMU sample");
        }
        for k in self.next..self.scans.len() {
            self.skip(k, self.scans.stamp_ns(k), "after the last IMU sample");
        }
        self.next = self.scans.len();
    }

    /// The run's bookkeeping, every scan not reached booked as after the last IMU sample.
    pub(crate) fn into_run(mut self) -> Run {
        self.skip_remaining();
        self.run
    }

    /// The last processed scan, deskewed to its reference stamp (LiDAR clock), when the feed
    /// keeps them.
    pub(crate) fn take_deskewed(&mut self) -> Option<(u64, DeskewedScan)> {
        self.deskewed.take()
    }

    pub(crate) fn skip(&mut self, index: usize, stamp_ns: u64, why: &str) {
        self.run.skipped.push(format!(
            "lidar0 scan {} ({}): {why}",
            stamp_ns,
            self.scans.name(index)
        ));
        let t_s = stamp_ns.saturating_sub(self.first_imu_ns) as f64 * 1e-9;
        self.records.push(ScanRecord::unmatched(
            stamp_ns,
            stamp_ns,
            t_s,
            0,
            why.to_string(),
        ));
    }
}
