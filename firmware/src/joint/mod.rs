//! The joint layout on the device (issue 12 item 3, issue 13 item 5): `JointEkf<f32>`
//! (IMU; sensor 0 = LiDAR, sensor 1 = camera, each with extrinsic and time offset; four
//! clones; the board as static frame 0; 59 error states) over a deterministic joint sequence
//! ([`scenario`]), with the self-test's checks ([`selftest`]) and the layout's memory as a
//! compile-time constant.

pub mod scenario;
pub mod selftest;

use msreg_estimator::filter::JointEkf;
use msreg_estimator::na::Vector6;
use msreg_estimator::Layout;

use scenario::JointConfig;
use selftest::{JointCounts, JointSetup, SensorResult};

/// The joint filter the firmware runs.
pub type JointFilter = JointEkf<f32>;
/// The camera (corner reprojections).
pub use msreg_estimator::JOINT_CAMERA as CAMERA;
/// The LiDAR (relative poses, board planes).
pub use msreg_estimator::JOINT_LIDAR as LIDAR;
/// The static frame of the board.
pub use msreg_estimator::TARGET_FRAME as BOARD_FRAME;
/// Error states of the joint layout.
pub const JOINT_STATES: usize = Layout::<2, 4>::dim_with_frames(1);
/// Bytes of one `JointEkf<f32>`: a compile-time fact of the layout.
pub const JOINT_FILTER_BYTES: usize = size_of::<JointFilter>();
/// Bytes of its covariance alone (`N x N` f32).
pub const JOINT_COVARIANCE_BYTES: usize = JOINT_STATES * JOINT_STATES * 4;

/// [`JOINT_FILTER_BYTES`] as a symbol in `.rodata`, which `tools/firmware.sh size` reads
/// from the ELF (the self-test reads it too, which keeps it linked).
#[no_mangle]
#[used]
pub static MSREG_JOINT_FILTER_BYTES: u32 = JOINT_FILTER_BYTES as u32;

/// Everything the joint self-test found.
#[derive(Clone, Copy, Debug)]
pub struct JointReport {
    /// What the filter processed.
    pub counts: JointCounts,
    /// Events the generator or the feeder lost (0 in a valid sequence).
    pub dropped: u32,
    /// Measurements never due by the end of the sequence.
    pub left: u32,
    /// LiDAR extrinsic and time offset.
    pub lidar: SensorResult,
    /// Camera extrinsic and time offset.
    pub camera: SensorResult,
    /// Board pose error per axis over its 1-sigma.
    pub board: Option<Vector6<f32>>,
    /// Covariance health at the end.
    pub covariance: crate::selftest::CovarianceCheck,
}

/// Runs the joint filter over `events` (the sequence of `setup`) and reports.
pub fn run(
    setup: &JointSetup,
    filter: &mut JointFilter,
    events: &mut scenario::JointScenario,
) -> JointReport {
    let mut counts = JointCounts::default();
    let (left, dropped) = selftest::drive(filter, events.by_ref(), |filter, event| {
        let outcome = selftest::feed(filter, setup, event);
        counts.record(event, &outcome);
    });
    assess(
        setup,
        filter,
        counts,
        events.dropped() + dropped,
        left as u32,
    )
}

/// The report at the end of a run. Out of line: the covariance copies it reads (14 KB each)
/// must not sit in the frame that runs the updates.
#[inline(never)]
fn assess(
    setup: &JointSetup,
    filter: &JointFilter,
    counts: JointCounts,
    dropped: u32,
    left: u32,
) -> JointReport {
    JointReport {
        counts,
        dropped,
        left,
        lidar: selftest::sensor_result(filter, &setup.config, LIDAR),
        camera: selftest::sensor_result(filter, &setup.config, CAMERA),
        board: selftest::board_normalized(filter, &setup.config),
        covariance: selftest::covariance_check(filter),
    }
}

/// Convergence: final errors at most this fraction of the prior's (as the pose self-test).
pub const MAX_ERROR_FRACTION: f32 = 0.25;

/// Named pass/fail checks of a [`JointReport`].
pub struct JointChecks {
    /// `(name, passed)` per check.
    pub items: [(&'static str, bool); 6],
}

impl JointChecks {
    /// True when every check passed.
    pub fn all_passed(&self) -> bool {
        self.items.iter().all(|(_, ok)| *ok)
    }
}

fn converged(r: &SensorResult) -> bool {
    r.final_error.rotation <= MAX_ERROR_FRACTION * r.initial_error.rotation
        && r.final_error.translation <= MAX_ERROR_FRACTION * r.initial_error.translation
}

impl JointReport {
    /// Evaluates the checks against the expected counts of `config`.
    pub fn checks(&self, config: &JointConfig) -> JointChecks {
        let c = &self.counts;
        let counts_ok = c.errors == 0
            && self.left == 0
            && u64::from(c.imu_samples) == config.base.imu_count()
            && c.anchors == 1
            && u64::from(c.relative_poses.calls) == config.increment_count()
            && u64::from(c.images.calls) == config.image_count()
            && u64::from(c.planes.calls) == config.plane_count();
        let all_accepted = [c.relative_poses, c.images, c.planes]
            .iter()
            .all(|t| t.accepted == t.calls);
        let board_finite = self.board.is_some_and(|b| b.iter().all(|e| e.is_finite()));
        JointChecks {
            items: [
                (
                    "joint sequence valid: every corner inside the image, nothing dropped",
                    c.corners_outside == 0 && self.dropped == 0,
                ),
                (
                    "every IMU sample, pose, image and plane processed without error",
                    counts_ok,
                ),
                ("every joint update accepted by the gate", all_accepted),
                (
                    "LiDAR extrinsic errors at most a quarter of the prior's",
                    converged(&self.lidar),
                ),
                (
                    "camera extrinsic errors at most a quarter of the prior's",
                    converged(&self.camera),
                ),
                // Both extrinsics and the board are reported, not checked, against their
                // sigmas: one draw cannot tell a consistent filter (the relinearising image
                // update this replaced passed a LiDAR 3-sigma check here while 25 of 40 noise
                // seeds failed it). hil-tests/tests/joint_consistency.rs runs these modules
                // over 40 seeds on the host; what is left from the 3 deg camera prior is an
                // open finding (docs/firmware.md, "Joint layout: consistency over 40 seeds").
                (
                    "joint covariance symmetric, finite, positive diagonal; board estimated",
                    self.covariance.passed() && board_finite,
                ),
            ],
        }
    }
}
