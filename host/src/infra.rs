//! Registration of a building's static infrastructure cameras (dissertation chapter 6):
//! a robot with an upward fisheye `F` (cam0) and an ArUco marker `M` drives a loop under
//! the cameras; its VO keyframes (COLMAP text model), the cameras' marker detections and
//! the blobs the cameras make in `F` register every camera in one metric frame.
//! Layout and result keys: docs/formats.md, section 2.9; method and
//! numbers: docs/infra.md.

pub mod align;
pub mod ba;
pub mod ba_solver;
pub mod blocksym;
pub mod colmap;
pub mod dataset;
pub mod detect;
pub mod eval;
pub mod init;
pub mod interp;
pub mod io;
pub mod motion;
pub mod pipeline;
pub mod render;
pub mod scene;
pub mod sim;
pub mod topview;
