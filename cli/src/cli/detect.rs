//! `msreg detect checkerboard` / `msreg detect aprilgrid`: Kalibr-target corners of images
//! as CSV (`image,corner_id,u,v`, Kalibr's corner ids), one line per corner; images without
//! a full checkerboard (or with fewer than 4 AprilGrid tags) are reported on stderr with the
//! reason and produce no lines. The target is the one `target.yaml` names.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, ensure, Context};
use clap::Args;
use msreg_host::camera_yaml::{read_camera_yaml, read_target_yaml, Target};
use msreg_host::vision::frames::detect_corners;
use msreg_host::vision::{DetectorParams, GrayImage};

/// Arguments of `msreg detect checkerboard` and `msreg detect aprilgrid`.
#[derive(Args)]
pub struct DetectCornersArgs {
    /// Images (PNG or JPEG, grey or colour).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Kalibr target.yaml (target_type checkerboard or aprilgrid).
    #[arg(long)]
    target: PathBuf,
    /// Kalibr camera.yaml: checks the image size (the detector works on the raw image).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Write the CSV here instead of stdout.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Refine with OpenCV's fixed 23 x 23 window (`cornerSubPix` winSize 11) instead of a
    /// window capped at half the corner spacing (docs/checkerboard.md).
    #[arg(long)]
    opencv_window: bool,
}

/// Runs the detector; returns how many images had the target. Errors are bad input.
pub fn run(args: &DetectCornersArgs) -> anyhow::Result<usize> {
    let target = read_target_yaml(&args.target)?;
    if let Target::Board(_) = target {
        bail!(
            "{}: target_type must be checkerboard or aprilgrid",
            args.target.display()
        );
    }
    let camera = args.camera.as_deref().map(read_camera_yaml).transpose()?;
    let params = if args.opencv_window {
        DetectorParams::opencv_compatible()
    } else {
        DetectorParams::default()
    };
    let mut csv = String::from("image,corner_id,u,v\n");
    let mut detected = 0;
    for path in &args.images {
        let image = GrayImage::load(path)?;
        if let Some(camera) = &camera {
            let size = (image.width() as u32, image.height() as u32);
            ensure!(
                camera.resolution == size,
                "{}: {}x{} image, but the camera.yaml resolution is {}x{}",
                path.display(),
                size.0,
                size.1,
                camera.resolution.0,
                camera.resolution.1
            );
        }
        match detect_corners(&image, &target, &params) {
            Ok(found) => {
                detected += 1;
                for (id, p) in found.ids.iter().zip(&found.pixels) {
                    writeln!(csv, "{},{id},{:.4},{:.4}", path.display(), p.x, p.y)?;
                }
            }
            Err(reason) => eprintln!("{}: no target: {reason}", path.display()),
        }
    }
    match &args.output {
        Some(out) => {
            std::fs::write(out, csv).with_context(|| format!("{}: cannot write", out.display()))?
        }
        None => print!("{csv}"),
    }
    Ok(detected)
}
