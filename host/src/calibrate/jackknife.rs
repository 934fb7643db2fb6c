//! The data-driven model error of an IMU-extrinsic calibration (issue 34, item 2): how far
//! apart the estimates of independent time blocks of one recording really are, against what
//! the filter's covariance says they should be.
//!
//! The filter's covariance holds only as far as its measurement model does. On real data it
//! does not: on EuRoC `imu_april` camera-IMU reported 0.003 deg / 0.08 mm while two halves of
//! the recording differed by 0.04 deg / 0.9 mm (docs/camera_imu.md). Errors outside the model
//! (intrinsics, IMU scale and misalignment, corner errors correlated within an image and
//! from image to image) act on the estimate like extra noise whose size only the data show.
//!
//! The estimate here, the **time-block spread**: the recording is cut into `K` blocks of
//! about [`BLOCK_S`]; the pipeline runs on each block alone (its own start, the same prior),
//! giving `K` independent estimates `theta_k` with covariances `P_k`. With `I_k = P_k^-1`,
//! `P_w = (sum I_k)^-1` and `theta_w = P_w sum I_k theta_k`, the spread of the blocks about
//! their information-weighted mean gives the covariance of that mean
//! `C = K / (K - 1) sum P_w I_k (theta_k - theta_w)(theta_k - theta_w)^T I_k P_w` (the
//! batch-means form of the grouped jackknife and of the cluster sandwich: for a linear
//! estimator the three agree to first order). Per axis, the ratio `C_ii / (P_w)_ii` is the
//! factor by which the data's variance exceeds the filter's: 1 on average when the model
//! holds, larger when it does not. The whole run's written covariance is the filter's with
//! each axis' sigma scaled by `sqrt(max(1, ratio))` (the filter's correlations kept): per
//! axis, the larger of the filter's sigma and the data's. It costs one extra pass over the
//! recording (the leave-one-block-out jackknife costs `K`).
//!
//! What it cannot see: an error common to every block (a wrong intrinsic that biases every
//! block alike). It is a floor under the honest sigma, not a bound on the error to a
//! reference.

use nalgebra::{Isometry3, Matrix6, SMatrix, SVector};
use serde::Serialize;

/// 7x7: the extrinsic's `[dtheta (right, rad); dp (m)]` and the time offset (s).
pub type Matrix7 = SMatrix<f64, 7, 7>;
/// An error in the coordinates of [`Matrix7`].
pub type Vector7 = SVector<f64, 7>;

/// Length of one time block, s: long enough that a block's own start (the IMU alignment,
/// the first images) is a small part of it, short enough for ~10 blocks in a minute.
pub const BLOCK_S: f64 = 6.0;
/// Fewest blocks: below it the spread says too little (3 degrees of freedom per axis).
pub const MIN_BLOCKS: usize = 4;
/// Most blocks.
pub const MAX_BLOCKS: usize = 12;

/// One estimate of an extrinsic and time offset with its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The transform.
    pub transform: Isometry3<f64>,
    /// The time offset, s.
    pub time_offset_s: f64,
    /// Covariance of `[dtheta (right); dp; dt_d]`.
    pub covariance: Matrix7,
}

impl Estimate {
    /// From the 6x6 extrinsic covariance and the time offset's sigma (uncorrelated).
    pub fn new(
        transform: Isometry3<f64>,
        covariance: &Matrix6<f64>,
        time_offset_s: f64,
        time_offset_sigma_s: f64,
    ) -> Self {
        let mut c = Matrix7::zeros();
        c.fixed_view_mut::<6, 6>(0, 0).copy_from(covariance);
        c[(6, 6)] = time_offset_sigma_s * time_offset_sigma_s;
        Self {
            transform,
            time_offset_s,
            covariance: c,
        }
    }

    /// The error of `self` against `reference`: `[Log(R_ref^-1 R); p - p_ref; t_d - t_d_ref]`.
    pub fn minus(&self, reference: &Estimate) -> Vector7 {
        let r = (reference.transform.rotation.inverse() * self.transform.rotation).scaled_axis();
        let p = self.transform.translation.vector - reference.transform.translation.vector;
        Vector7::from_column_slice(&[
            r.x,
            r.y,
            r.z,
            p.x,
            p.y,
            p.z,
            self.time_offset_s - reference.time_offset_s,
        ])
    }

    /// The 6x6 extrinsic block of the covariance.
    pub fn extrinsic_covariance(&self) -> Matrix6<f64> {
        self.covariance.fixed_view::<6, 6>(0, 0).into_owned()
    }

    /// The time offset's sigma, s.
    pub fn time_offset_sigma_s(&self) -> f64 {
        self.covariance[(6, 6)].max(0.0).sqrt()
    }
}

/// `count` equal time blocks `[from, to)` covering `first_ns..=last_ns` (the last one
/// closed), `count` from the duration at [`BLOCK_S`] within [`MIN_BLOCKS`]-[`MAX_BLOCKS`].
pub fn time_blocks(first_ns: u64, last_ns: u64) -> Vec<(u64, u64)> {
    let span = last_ns.saturating_sub(first_ns);
    let count = ((span as f64 * 1e-9 / BLOCK_S).round() as usize).clamp(MIN_BLOCKS, MAX_BLOCKS);
    (0..count)
        .map(|k| {
            let at = |k: usize| first_ns + (span as u128 * k as u128 / count as u128) as u64;
            let to = if k + 1 == count {
                last_ns.saturating_add(1)
            } else {
                at(k + 1)
            };
            (at(k), to)
        })
        .collect()
}

/// The spread of independent block estimates about their information-weighted mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockSpread {
    /// Blocks used.
    pub blocks: usize,
    /// `P_w`: the covariance of the weighted mean by the filter's own covariances.
    pub filter: Matrix7,
    /// `C`: the same from the blocks' spread (module docs).
    pub data: Matrix7,
}

impl BlockSpread {
    /// The spread of `blocks`, `None` with fewer than [`MIN_BLOCKS`] or a covariance that
    /// does not invert. An axis a block holds (variance zero, e.g. a time offset not
    /// estimated) takes no part: its ratio is 0.
    pub fn of(blocks: &[Estimate]) -> Option<Self> {
        if blocks.len() < MIN_BLOCKS {
            return None;
        }
        let reference = blocks[0];
        // Unit scale per axis: the covariances span 1e-12 (s^2) to 1e-5 (rad^2).
        let scale = Vector7::from_fn(|i, _| {
            let v = blocks.iter().map(|b| b.covariance[(i, i)]).sum::<f64>() / blocks.len() as f64;
            if v.is_finite() && v > 0.0 {
                v.sqrt()
            } else {
                0.0
            }
        });
        let held = |i: usize| scale[i] == 0.0;
        let scaled = |b: &Estimate| {
            Matrix7::from_fn(|r, c| match (held(r), held(c)) {
                (false, false) => b.covariance[(r, c)] / (scale[r] * scale[c]),
                (true, true) if r == c => 1.0,
                _ => 0.0,
            })
        };
        let mut informations = Vec::with_capacity(blocks.len());
        let mut deviations = Vec::with_capacity(blocks.len());
        for b in blocks {
            informations.push(scaled(b).try_inverse()?);
            let d = b.minus(&reference);
            deviations.push(Vector7::from_fn(|i, _| {
                if held(i) {
                    0.0
                } else {
                    d[i] / scale[i]
                }
            }));
        }
        let total: Matrix7 = informations.iter().sum();
        let pooled = total.try_inverse()?;
        let weighted: Vector7 = informations
            .iter()
            .zip(&deviations)
            .map(|(i, d)| i * d)
            .sum();
        let mean = pooled * weighted;
        let k = blocks.len() as f64;
        let data: Matrix7 = informations
            .iter()
            .zip(&deviations)
            .map(|(i, d)| {
                let g = pooled * i * (d - mean);
                g * g.transpose()
            })
            .sum::<Matrix7>()
            * (k / (k - 1.0));
        let unscale = |m: &Matrix7| Matrix7::from_fn(|r, c| m[(r, c)] * scale[r] * scale[c]);
        Some(Self {
            blocks: blocks.len(),
            filter: unscale(&pooled),
            data: unscale(&data),
        })
    }

    /// Per axis, the data's variance over the filter's (0 on a held axis).
    pub fn ratio(&self) -> Vector7 {
        Vector7::from_fn(|i, _| {
            let f = self.filter[(i, i)];
            if f > 0.0 {
                self.data[(i, i)] / f
            } else {
                0.0
            }
        })
    }
}

/// `covariance` with each axis' sigma scaled by `sqrt(max(1, ratio))`, its correlations
/// kept: per axis the larger of the filter's sigma and the data's.
pub fn inflate(covariance: &Matrix7, ratio: &Vector7) -> Matrix7 {
    let d = ratio.map(|r| {
        if r.is_finite() {
            r.max(1.0).sqrt()
        } else {
            1.0
        }
    });
    Matrix7::from_fn(|r, c| covariance[(r, c)] * d[r] * d[c])
}

/// What the report says of the model error, in the frame of the result file's transform
/// (rotation about its right-hand frame's axes, translation along its left-hand frame's).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelErrorReport {
    /// How it was estimated.
    pub method: &'static str,
    /// Blocks the recording was cut into, and those whose run gave an estimate.
    pub blocks: usize,
    /// Blocks whose run gave an estimate.
    pub blocks_used: usize,
    /// Why the others did not.
    pub skipped: Vec<String>,
    /// Per axis (rotation x, y, z, translation x, y, z, time offset), the data's variance
    /// over the filter's; the written sigma is the filter's times `sqrt(max(1, ratio))`.
    pub variance_ratio: [f64; 7],
    /// The filter's own 1-sigma, deg / m / s.
    pub filter_sigma_rot_deg: [f64; 3],
    /// The filter's own translation 1-sigma, m.
    pub filter_sigma_trans_m: [f64; 3],
    /// The filter's own time-offset 1-sigma, s.
    pub filter_sigma_time_offset_s: f64,
    /// The data's 1-sigma: the filter's times `sqrt(ratio)`, deg.
    pub data_sigma_rot_deg: [f64; 3],
    /// The data's translation 1-sigma, m.
    pub data_sigma_trans_m: [f64; 3],
    /// The data's time-offset 1-sigma, s.
    pub data_sigma_time_offset_s: f64,
    /// The written (result file's) 1-sigma, per axis the larger of the two, deg.
    pub sigma_rot_deg: [f64; 3],
    /// The written translation 1-sigma, m.
    pub sigma_trans_m: [f64; 3],
    /// The written time-offset 1-sigma, s.
    pub sigma_time_offset_s: f64,
    /// Wall time of the block runs, s.
    pub time_s: f64,
}

/// The written covariance and the report of the whole run's estimate `full` (filter
/// covariance) from the block runs `blocks` (`Err`: why a block gave none; the spread is
/// skipped with fewer than [`MIN_BLOCKS`] estimates, and the filter's covariance written).
pub fn model_error(
    full: &Estimate,
    blocks: &[Result<Estimate, String>],
    time_s: f64,
) -> (Matrix7, ModelErrorReport) {
    let estimates: Vec<Estimate> = blocks
        .iter()
        .filter_map(|b| b.as_ref().ok())
        .copied()
        .collect();
    let mut skipped: Vec<String> = blocks
        .iter()
        .enumerate()
        .filter_map(|(k, b)| b.as_ref().err().map(|why| format!("block {k}: {why}")))
        .collect();
    let ratio = match BlockSpread::of(&estimates) {
        Some(spread) => spread.ratio(),
        None => {
            skipped.push(format!(
                "{} block estimates, {MIN_BLOCKS} needed: the filter's covariance is written",
                estimates.len()
            ));
            Vector7::zeros()
        }
    };
    let written = inflate(&full.covariance, &ratio);
    let sd = |m: &Matrix7, i: usize, s: f64| m[(i, i)].max(0.0).sqrt() * s;
    let data = Matrix7::from_fn(|r, c| {
        full.covariance[(r, c)] * ratio[r].max(0.0).sqrt() * ratio[c].max(0.0).sqrt()
    });
    // As the result file converts them (`ExtrinsicEstimate::from_covariance`).
    let rot = |m: &Matrix7| std::array::from_fn(|i| sd(m, i, 1.0).to_degrees());
    let trans = |m: &Matrix7| std::array::from_fn(|i| sd(m, i + 3, 1.0));
    let report = ModelErrorReport {
        method: "time-block spread: the pipeline on each block alone, the blocks' spread about \
                 their weighted mean against their own covariances",
        blocks: blocks.len(),
        blocks_used: estimates.len(),
        skipped,
        variance_ratio: ratio.into(),
        filter_sigma_rot_deg: rot(&full.covariance),
        filter_sigma_trans_m: trans(&full.covariance),
        filter_sigma_time_offset_s: sd(&full.covariance, 6, 1.0),
        data_sigma_rot_deg: rot(&data),
        data_sigma_trans_m: trans(&data),
        data_sigma_time_offset_s: sd(&data, 6, 1.0),
        sigma_rot_deg: rot(&written),
        sigma_trans_m: trans(&written),
        sigma_time_offset_s: sd(&written, 6, 1.0),
        time_s,
    };
    (written, report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// `base` moved by the error `e` as [`Estimate::minus`] reads it.
    fn moved(base: &Isometry3<f64>, e: &Vector7) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(base.translation.vector + Vector3::new(e[3], e[4], e[5])),
            base.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(e[0], e[1], e[2])),
        )
    }

    /// `count` blocks drawn around `base` with errors of covariance `truth`, each claiming
    /// `claimed`.
    fn blocks(truth: &Matrix7, claimed: &Matrix7, count: usize, seed: u64) -> Vec<Estimate> {
        let base = Isometry3::from_parts(
            Translation3::new(0.05, -0.02, 0.01),
            UnitQuaternion::from_euler_angles(-1.5, 0.03, -1.6),
        );
        let l = truth.cholesky().expect("positive definite").l();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..count)
            .map(|_| {
                let z = Vector7::from_fn(|_, _| StandardNormal.sample(&mut rng));
                let e = l * z;
                Estimate {
                    transform: moved(&base, &e),
                    time_offset_s: 0.004 + e[6],
                    covariance: *claimed,
                }
            })
            .collect()
    }

    fn claimed() -> Matrix7 {
        let sd = [5e-5, 6e-5, 4e-5, 1e-4, 2e-4, 1.5e-4, 5e-6];
        let mut c = Matrix7::from_fn(|r, c| sd[r] * sd[c] * if r == c { 1.0 } else { 0.3 });
        c.fixed_view_mut::<1, 6>(6, 0).fill(0.0);
        c.fixed_view_mut::<6, 1>(0, 6).fill(0.0);
        c
    }

    #[test]
    fn time_blocks_cover_the_recording() {
        // Given a 71.9 s recording
        let first = 1_000_000_000_u64;
        let last = first + 71_900_000_000;
        // When it is cut
        let b = time_blocks(first, last);
        // Then 12 blocks of ~6 s tile it without gap, the last one closed
        assert_eq!(b.len(), 12);
        assert_eq!(b[0].0, first);
        assert_eq!(b[11].1, last + 1);
        assert!(b.windows(2).all(|w| w[0].1 == w[1].0));
        // and a 10 s recording still has 4
        assert_eq!(time_blocks(first, first + 10_000_000_000).len(), MIN_BLOCKS);
    }

    #[test]
    fn the_spread_of_consistent_blocks_matches_their_covariance() {
        // Given 10 blocks whose errors have exactly the covariance they claim, over 400 draws
        let c = claimed();
        let mut ratio = Vector7::zeros();
        let draws = 400;
        for seed in 0..draws {
            let spread = BlockSpread::of(&blocks(&c, &c, 10, seed)).expect("spread");
            // The filter's pooled covariance is the blocks' over 10
            assert!((spread.filter - c / 10.0).amax() < 1e-12 * c.amax());
            ratio += spread.ratio();
        }
        // Then the mean ratio is 1 per axis (sampling sd of the mean: sqrt(2 / 9 / 400) =
        // 0.024; measured within 0.05)
        let mean = ratio / draws as f64;
        assert!(mean.iter().all(|r| (r - 1.0).abs() < 0.08), "{mean}");
    }

    #[test]
    fn the_spread_finds_errors_the_covariance_does_not_hold() {
        // Given blocks whose translation errors are 3x what they claim
        let c = claimed();
        let mut truth = c;
        for i in 3..6 {
            for j in 0..7 {
                truth[(i, j)] *= 3.0;
                truth[(j, i)] *= 3.0;
            }
        }
        let mut ratio = Vector7::zeros();
        for seed in 0..200 {
            ratio += BlockSpread::of(&blocks(&truth, &c, 10, 1000 + seed))
                .expect("spread")
                .ratio();
        }
        let mean = ratio / 200.0;
        // Then the translation ratio is ~9, the rotation and time offset ones ~1
        assert!((3..6).all(|i| (mean[i] - 9.0).abs() < 1.0), "{mean}");
        assert!(
            [0, 1, 2, 6].iter().all(|&i| (mean[i] - 1.0).abs() < 0.2),
            "{mean}"
        );
        // And the written covariance scales those sigmas, not the others
        let full = Estimate {
            covariance: c / 10.0,
            ..blocks(&c, &c, 1, 1)[0]
        };
        let runs: Vec<Result<Estimate, String>> =
            blocks(&truth, &c, 10, 7).into_iter().map(Ok).collect();
        let (written, report) = model_error(&full, &runs, 0.0);
        for i in 0..7 {
            let r = report.variance_ratio[i].max(1.0);
            assert!((written[(i, i)] - full.covariance[(i, i)] * r).abs() < 1e-9 * written[(i, i)]);
        }
        assert_eq!(report.blocks_used, 10);
        assert!(report.sigma_trans_m[1] >= report.filter_sigma_trans_m[1]);
    }

    #[test]
    fn a_held_axis_and_too_few_blocks_are_handled() {
        // Given blocks that hold the time offset (variance 0)
        let mut c = claimed();
        c[(6, 6)] = 0.0;
        let mut truth = c;
        truth[(6, 6)] = 1e-30;
        let b = blocks(&truth, &c, 6, 3);
        // Then the spread exists with ratio 0 there
        let spread = BlockSpread::of(&b).expect("spread");
        assert!(spread.ratio()[6] == 0.0 && spread.ratio()[0] > 0.0);
        // And with three blocks there is none: the filter's covariance is written
        let runs: Vec<Result<Estimate, String>> =
            vec![Ok(b[0]), Ok(b[1]), Err("diverged".into()), Ok(b[2])];
        let (written, report) = model_error(&b[0], &runs, 0.0);
        assert_eq!(written, b[0].covariance);
        assert_eq!(report.skipped.len(), 2, "{:?}", report.skipped);
        assert!(report.skipped[0].starts_with("block 2"));
    }
}
