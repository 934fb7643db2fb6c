//! `msreg detect aruco` and `msreg detect blobs`: ArUco markers
//! (`image,id,u0,v0,u1,v1,u2,v2,u3,v3`, corners in OpenCV order) and bright blobs
//! (`image,u,v,area,peak`) of images as CSV. Every image is read before anything is
//! printed, so bad input (an unreadable image) gives no partial output.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use msreg_host::vision::aruco::{detect_markers, ArucoParams, Dictionary};
use msreg_host::vision::blobs::{detect_blobs, BlobParams};
use msreg_host::vision::GrayImage;

/// Arguments of `msreg detect aruco`.
#[derive(Args)]
pub struct DetectArucoArgs {
    /// Images (PNG or JPEG, grey or colour).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Dictionary: DICT_4X4_50, DICT_6X6_250 or DICT_ARUCO_ORIGINAL.
    #[arg(long)]
    dictionary: Dictionary,
    /// Leave the integer contour corners (no sub-pixel refinement).
    #[arg(long)]
    no_refine: bool,
    /// Write the CSV here instead of stdout.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Arguments of `msreg detect blobs`.
#[derive(Args)]
pub struct DetectBlobsArgs {
    /// Images (PNG or JPEG, grey or colour).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Grey level (0-255) above which pixels belong to blobs.
    #[arg(long, default_value_t = 200.0)]
    threshold: f32,
    /// Smallest blob, pixels.
    #[arg(long, default_value_t = 3)]
    min_area: usize,
    /// Largest blob, pixels.
    #[arg(long, default_value_t = 2000)]
    max_area: usize,
    /// Largest ratio of the blob's major to minor axis.
    #[arg(long, default_value_t = 3.0)]
    max_elongation: f64,
    /// Only blobs inside this image circle: `cx,cy,radius` in pixels (fisheye).
    #[arg(long, value_delimiter = ',', num_args = 3)]
    image_circle: Option<Vec<f64>>,
    /// Write the CSV here instead of stdout.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Runs the marker detector; returns the number of markers. Errors are bad input.
pub fn run_aruco(args: &DetectArucoArgs) -> anyhow::Result<usize> {
    let params = ArucoParams {
        subpix: if args.no_refine {
            None
        } else {
            ArucoParams::default().subpix
        },
        ..ArucoParams::default()
    };
    let mut csv = String::from("image,id,u0,v0,u1,v1,u2,v2,u3,v3\n");
    let mut count = 0;
    for path in &args.images {
        let image = GrayImage::load(path)?;
        let markers = detect_markers(&image, args.dictionary, &params);
        if markers.is_empty() {
            eprintln!("{}: no {} marker", path.display(), args.dictionary);
        }
        for m in &markers {
            write!(csv, "{},{}", path.display(), m.id)?;
            for c in &m.corners {
                write!(csv, ",{:.4},{:.4}", c.x, c.y)?;
            }
            csv.push('\n');
        }
        count += markers.len();
    }
    emit(&args.output, csv)?;
    Ok(count)
}

/// Runs the blob detector; returns the number of blobs. Errors are bad input.
pub fn run_blobs(args: &DetectBlobsArgs) -> anyhow::Result<usize> {
    let params = BlobParams {
        threshold: args.threshold,
        min_area: args.min_area,
        max_area: args.max_area,
        max_elongation: args.max_elongation,
        image_circle: args.image_circle.as_ref().map(|c| (c[0], c[1], c[2])),
        ..BlobParams::default()
    };
    let mut csv = String::from("image,u,v,area,peak\n");
    let mut count = 0;
    for path in &args.images {
        let image = GrayImage::load(path)?;
        let blobs = detect_blobs(&image, &params);
        for b in &blobs {
            writeln!(
                csv,
                "{},{:.4},{:.4},{},{:.0}",
                path.display(),
                b.u,
                b.v,
                b.area,
                b.peak
            )?;
        }
        count += blobs.len();
    }
    emit(&args.output, csv)?;
    Ok(count)
}

fn emit(output: &Option<PathBuf>, csv: String) -> anyhow::Result<()> {
    match output {
        Some(out) => {
            std::fs::write(out, csv).with_context(|| format!("{}: cannot write", out.display()))
        }
        None => {
            print!("{csv}");
            Ok(())
        }
    }
}
