//! `satmap-sim evaluate`: Chamfer-AP of a predictions file against a ground-truth file, both in
//! MapTR's results JSON layout (`eval::maptr_json`); prints the table and optionally writes the
//! report as JSON.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::eval::{EvalReport, evaluate_at, read_samples};

/// Arguments of `evaluate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Predictions: MapTR results JSON (with `confidence_level`).
    #[arg(long)]
    pub predictions: PathBuf,
    /// Ground truth: same layout, `confidence_level` optional (e.g. a scenario's
    /// `ground_truth.json`).
    #[arg(long)]
    pub gt: PathBuf,
    /// Chamfer thresholds, metres.
    #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 1.5])]
    pub thresholds_m: Vec<f64>,
    /// Write the report here as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Score and print.
///
/// # Errors
/// Unreadable or malformed input files, or the report cannot be written.
pub fn run(args: &Args) -> Result<()> {
    let predictions = read_samples(&args.predictions)?;
    let gt = read_samples(&args.gt)?;
    let report = evaluate_at(&predictions, &gt, &args.thresholds_m);
    print!("{}", format_report(&report));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text).with_context(|| path.display().to_string())?;
    }
    Ok(())
}

/// The report as a text table (AP in percent, like the papers).
#[must_use]
pub fn format_report(report: &EvalReport) -> String {
    let mut s = format!("{:<14}", "class");
    for t in &report.thresholds_m {
        s += &format!("{:>9}", format!("AP@{t}"));
    }
    s += &format!("{:>9}{:>8}{:>8}\n", "AP", "n_gt", "n_pred");
    for c in &report.classes {
        s += &format!("{:<14}", c.class.name());
        for ap in &c.ap_per_threshold {
            s += &format!("{:>9.2}", ap * 100.0);
        }
        s += &format!(
            "{:>9.2}{:>8}{:>8}\n",
            c.ap * 100.0,
            c.num_gt,
            c.num_predictions
        );
    }
    s += &format!(
        "mAP {:.2} over {} samples\n",
        report.mean_ap * 100.0,
        report.num_samples
    );
    s
}
