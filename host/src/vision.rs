//! Computer vision for camera calibration (chapter 4): grey images, checkerboard detection
//! with sub-pixel corners in Kalibr order, PnP for the target pose (its covariance feeds the
//! motion-based update, eq. 4.11-4.13), and a small renderer of checkerboards seen by a
//! [`msreg_estimator::camera::Camera`] for tests and the image simulator. Method and
//! measured accuracy: docs/checkerboard.md.

pub mod aprilgrid;
pub mod aruco;
pub mod blobs;
pub mod checkerboard;
pub mod components;
pub mod frames;
pub mod gray;
pub mod grid;
pub mod overlay;
pub mod pnp;
pub mod render;
pub mod saddle;
pub mod subpix;
pub mod target_svg;

pub use checkerboard::{detect_checkerboard, CheckerboardDetection, DetectorParams, NoDetection};
pub use frames::{detect_frames, CameraDataset, CameraInputError, FrameCorners, FrameResult};
pub use gray::{GrayImage, ImageLoadError};
pub use pnp::{solve_pnp, PnpError, PnpSolution};
