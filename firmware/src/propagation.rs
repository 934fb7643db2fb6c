//! The propagation the device runs (docs/estimator.md, "Propagation on the device"), in a
//! file of its own so the host-side harness that compiles the self-test modules
//! (hil-tests/examples/joint_seeds.rs) includes the same configuration.

use msreg_estimator::propagate::Rotations;
use msreg_estimator::FilterConfig;

/// The rotation functions of each IMU step by their power series instead of libm's
/// trigonometry, which evaluates in software `f64` on this FPU. Every filter the firmware
/// builds (the link's and the self-test's) goes through here.
pub fn device_config(mut fc: FilterConfig<f32>) -> FilterConfig<f32> {
    fc.rotations = Rotations::Series;
    fc
}
