//! `msreg check <dataset|bag>`: the dataset check of [`msreg_host::check`], printed; also
//! run by `msreg calibrate` before the calibration (errors stop it with exit code 2).

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use clap::Args;
use msreg_host::check::{check_dataset, CheckReport, Needs, Severity};

use super::outcome::progress_bar;

/// Arguments of `msreg check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Dataset directory, or a ROS 1 bag / MCAP file (read through a temporary dataset).
    pub dataset: PathBuf,
    /// Topics and noise files when the dataset argument is a bag.
    #[command(flatten)]
    pub bag: super::convert::BagFlags,
}

/// Runs the check and prints every finding; `Ok(false)` when one is an error.
pub fn run(args: &CheckArgs) -> anyhow::Result<bool> {
    let mut dataset = args.dataset.clone();
    let _converted = super::convert::dataset_from_bag(&mut dataset, &args.bag)?;
    let report = check_with_progress(&dataset, Needs::Any);
    for finding in &report.findings {
        println!("{}: {finding}", label(finding.severity()));
    }
    let errors = report.of(Severity::Error).count();
    let warnings = report.of(Severity::Warning).count();
    println!(
        "msreg check: {}: {errors} errors, {warnings} warnings",
        args.dataset.display()
    );
    Ok(errors == 0)
}

/// The check before a calibration: warnings are printed, errors returned as one error
/// (every error, each once).
pub fn before_calibration(dataset: &Path, needs: Needs) -> anyhow::Result<()> {
    let report = check_with_progress(dataset, needs);
    for warning in report.of(Severity::Warning) {
        eprintln!("msreg: warning: {warning}");
    }
    let errors: Vec<String> = report
        .of(Severity::Error)
        .map(ToString::to_string)
        .collect();
    match errors.len() {
        0 => Ok(()),
        1 => Err(anyhow!("{}", errors[0])),
        n => Err(anyhow!(
            "{} has {n} problems:\n  - {}",
            dataset.display(),
            errors.join("\n  - ")
        )),
    }
}

fn check_with_progress(dataset: &Path, needs: Needs) -> CheckReport {
    let bar = progress_bar(
        1000,
        "{spinner} checking the dataset [{bar:40}] {percent}% {elapsed}",
    );
    let report = check_dataset(dataset, needs, &|f| bar.set_position((f * 1000.0) as u64));
    bar.finish_and_clear();
    report
}

fn label(severity: Severity) -> &'static str {
    match severity {
        Severity::Error => "error",
        Severity::Warning => "warning",
        Severity::Note => "note",
    }
}
