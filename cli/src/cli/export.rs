//! `msreg export <result.yaml> --format kalibr|openvins|vins-fusion|urdf|tf [-o out]`: a
//! result file in the formats other tools read (docs/export.md). Every failure is bad input
//! (exit 2), named with the file and, for a missing key, the key.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use msreg_host::dataset::CalibrationResult;
use msreg_host::export::{self, ExportFormat};

/// Arguments of `msreg export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Result YAML (msreg's result file, docs/formats.md).
    pub result: PathBuf,
    /// Target format: kalibr, openvins, vins-fusion, urdf or tf.
    #[arg(long)]
    pub format: String,
    /// Output file (one-file formats) or directory (created; every format). Default: the
    /// current directory.
    #[arg(short, long, default_value = ".")]
    pub out: PathBuf,
}

/// Runs the export and prints the files written.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    let format: ExportFormat = args.format.parse()?;
    export_file(&args.result, format, &args.out)
}

/// `--format` of `msreg calibrate`: a format name as clap reads it.
pub fn parse_format(name: &str) -> Result<ExportFormat, String> {
    name.parse().map_err(|e: export::ExportError| e.to_string())
}

/// Exports the result file `result` as `format` into `out` (a file for one-file formats,
/// else a directory), warning about unknown keys and printing the files written.
pub fn export_file(result: &Path, format: ExportFormat, out: &Path) -> anyhow::Result<()> {
    let calibration = CalibrationResult::read(result)?;
    for key in calibration.unknown_keys() {
        eprintln!(
            "msreg: warning: {}: unknown key `{key}` ignored",
            result.display()
        );
    }
    let written = export::write(&calibration, format, out)
        .with_context(|| format!("{}: cannot export as {format}", result.display()))?;
    for path in written {
        println!("msreg: wrote {}", path.display());
    }
    Ok(())
}
