//! Mutual-information registration of a 3-D point set with intensity (LiDAR scan or prior
//! map) against a grey image (dissertation chapter 7, eq. 7.1-7.3; Pandey et al. for
//! targetless LiDAR-camera). One engine serves `msreg calibrate lidar-camera --targetless`
//! and the camera-in-a-prior-map registration. Method and numbers: docs/prior_map.md.
//!
//! - [`histogram`]: hard-binned MI / NMI and the cubic-B-spline (Parzen) smoothed MI.
//! - [`scene`]: points and image, projection through the estimator's camera models with
//!   bilinear sampling, the pose parametrisations and the analytic MI gradient.
//! - [`search`]: the parallel coarse-to-fine grid, the continuous 6-DoF refinement and
//!   the curvature sigmas with a per-DoF observability statement.
//! - [`basin`]: the wider-basin search (multi-candidate coarse-to-fine lattice on blurred
//!   images, flatness probes of the other DoFs) before the refinement.
//! - [`targetless`]: the LiDAR-camera dataset, run and overlay; [`cli`]: the command.
//! - [`markings`]: lane-marking crossings, an independent geometric check of an extrinsic
//!   on a road scene (used to judge the real reference).

pub mod basin;
pub mod histogram;
pub mod markings;
pub mod prior_map;
pub mod scene;
pub mod search;
pub mod synthetic;
pub mod targetless;

#[cfg(test)]
mod basin_tests;
#[cfg(test)]
mod tests;

pub use histogram::{hard_mi, BSplineHistogram, MiScore};
pub use scene::{equalize, MiScene, PoseParam};
pub use search::{grid_search, refine, GridAxis, GridScore, Observability, RefineOptions, Refined};
