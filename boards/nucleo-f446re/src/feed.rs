//! The feed seam on the board: each IMU sample read from the ICM-42688-P becomes the
//! estimator's `ImuSample<f32>` (`msreg_icm42688::estimator::imu_sample`, the conversion the
//! session makes for a host `ImuBatch` sample) and goes to the link session's filter.
//!
//! The session applies IMU samples only from host frames today: `Session::on_imu` is
//! private. The `session-local-imu` feature calls `Session::local_imu`, the public entry
//! point proposed in docs/firmware.md ("Flashing a real board", the session change); until
//! it exists, the default build converts the samples and counts them as not fed, and the
//! host drives the filter over the link as on QEMU.

use msreg_firmware::session::Session;
use msreg_icm42688::estimator::imu_sample;
use msreg_icm42688::Sample;

/// Feeds one sample; `true` when the filter took it (configured, accepted).
#[cfg(feature = "session-local-imu")]
pub fn feed<W: embedded_io::Write>(session: &mut Session, w: &mut W, s: &Sample) -> bool {
    session.local_imu(w, &imu_sample(s)).is_ok()
}

/// Feeds one sample; `true` when the filter took it. Without `session-local-imu` the
/// session has no entry for device samples: converted, not fed.
#[cfg(not(feature = "session-local-imu"))]
pub fn feed<W: embedded_io::Write>(_session: &mut Session, _w: &mut W, s: &Sample) -> bool {
    let _ = imu_sample(s);
    false
}
