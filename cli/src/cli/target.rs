//! `msreg target checkerboard|aprilgrid`: a printable target at exact size
//! ([`msreg_host::vision::target_svg`]) and its Kalibr `target.yaml`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use msreg_host::camera_yaml::{
    aprilgrid_yaml_string, checkerboard_yaml_string, AprilGridTarget, CheckerboardTarget,
};
use msreg_host::vision::target_svg::{target_svg, Page, PrintTarget};

/// `msreg target <kind>`.
#[derive(Debug, Subcommand)]
pub enum TargetCommand {
    /// A Kalibr checkerboard: `--rows` x `--cols` inner corners, `--square` metres.
    Checkerboard(CheckerboardArgs),
    /// A Kalibr AprilGrid (tag36h11): `--tag-cols` x `--tag-rows` tags of `--tag-size` metres,
    /// `--tag-spacing` of a tag apart.
    Aprilgrid(AprilGridArgs),
}

/// The `--page` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PageArg {
    /// 210 x 297 mm (portrait, or landscape when only that fits).
    A4,
    /// 297 x 420 mm.
    A3,
    /// 8.5 x 11 in.
    Letter,
    /// The pattern, its border and the caption, nothing more.
    Auto,
}

/// Options every target takes.
#[derive(Debug, Args)]
pub struct SheetArgs {
    /// Output SVG (exact physical size: width/height in mm, 1 user unit = 1 mm).
    #[arg(short, long, default_value = "target.svg")]
    pub output: PathBuf,
    /// The target.yaml to write beside it (default: target.yaml next to the SVG).
    #[arg(long)]
    pub yaml: Option<PathBuf>,
    /// Page size.
    #[arg(long, value_enum, default_value_t = PageArg::A4)]
    pub page: PageArg,
    /// White border around the pattern, mm.
    #[arg(long, default_value_t = 10.0)]
    pub border_mm: f64,
}

/// `msreg target checkerboard`.
#[derive(Debug, Args)]
pub struct CheckerboardArgs {
    /// Inner corner rows (Kalibr targetRows).
    #[arg(long, default_value_t = 6)]
    pub rows: usize,
    /// Inner corner columns (Kalibr targetCols).
    #[arg(long, default_value_t = 7)]
    pub cols: usize,
    /// Square side, metres (rowSpacingMeters = colSpacingMeters).
    #[arg(long, default_value_t = 0.03)]
    pub square: f64,
    /// Sheet options.
    #[command(flatten)]
    pub sheet: SheetArgs,
}

/// `msreg target aprilgrid`.
#[derive(Debug, Args)]
pub struct AprilGridArgs {
    /// Tags across (Kalibr tagCols).
    #[arg(long, default_value_t = 6)]
    pub tag_cols: usize,
    /// Tags down (Kalibr tagRows).
    #[arg(long, default_value_t = 6)]
    pub tag_rows: usize,
    /// Tag side (black border to black border), metres (Kalibr tagSize).
    #[arg(long, default_value_t = 0.022)]
    pub tag_size: f64,
    /// Gap between tags as a ratio of the tag size (Kalibr tagSpacing).
    #[arg(long, default_value_t = 0.3)]
    pub tag_spacing: f64,
    /// Sheet options.
    #[command(flatten)]
    pub sheet: SheetArgs,
}

/// Writes the SVG and the target.yaml; bad sizes and a page too small are errors (exit 2).
pub fn run(command: &TargetCommand) -> anyhow::Result<()> {
    let (target, yaml, sheet) = match command {
        TargetCommand::Checkerboard(a) => {
            let t = CheckerboardTarget {
                rows: a.rows,
                cols: a.cols,
                row_spacing_m: a.square,
                col_spacing_m: a.square,
                width_m: None,
                height_m: None,
            };
            (
                PrintTarget::Checkerboard(t),
                checkerboard_yaml_string(&t),
                &a.sheet,
            )
        }
        TargetCommand::Aprilgrid(a) => {
            let t = AprilGridTarget {
                tag_cols: a.tag_cols,
                tag_rows: a.tag_rows,
                tag_size_m: a.tag_size,
                tag_spacing: a.tag_spacing,
            };
            (
                PrintTarget::AprilGrid(t),
                aprilgrid_yaml_string(&t),
                &a.sheet,
            )
        }
    };
    let page = match sheet.page {
        PageArg::A4 => Page::A4,
        PageArg::A3 => Page::A3,
        PageArg::Letter => Page::Letter,
        PageArg::Auto => Page::Auto,
    };
    let drawn = target_svg(&target, page, sheet.border_mm)?;
    write(&sheet.output, &drawn.svg)?;
    let yaml_path = sheet.yaml.clone().unwrap_or_else(|| {
        sheet
            .output
            .parent()
            .unwrap_or(Path::new(""))
            .join("target.yaml")
    });
    write(&yaml_path, &yaml)?;
    eprintln!(
        "msreg: wrote {} ({:.1} x {:.1} mm; print at 100 %, no fit-to-page) and {}",
        sheet.output.display(),
        drawn.width_mm,
        drawn.height_mm,
        yaml_path.display()
    );
    Ok(())
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
}
