//! `satmap-sim evaluate`: Chamfer-AP of a predictions file against a ground-truth file, each in
//! MapTR's own layout (`{"results": [...]}`, `{"GTs": [...]}`) or ours (`{"results": {token:
//! ...}}`), told apart by content (`eval::maptr_files`); prints the table, optionally writes the
//! report as JSON and both inputs as MapTR's files.
//!
//! Several drives at once: `--predictions` and `--gt` repeated, paired by position; the samples
//! of all pairs are pooled into one evaluation (AP from the merged matches, as MapTR computes it
//! over a dataset; not a mean of per-drive APs), each token prefixed with its pair's index
//! (`0/000003`) so that frames of different drives never share a token.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::cli::drive::BadArgument;
use crate::eval::average_precision::NO_OVERLAP_DISTANCE_M;
use crate::eval::maptr_files::{MAPTR_GT_FILE, MAPTR_RESULTS_FILE};
use crate::eval::{EvalReport, LoadedFile, SampleSet, evaluate_at, read_file, write_maptr_pair};

/// Arguments of `evaluate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Predictions: MapTR's `nuscmap_results.json`, or our layout (with `confidence_level`).
    /// Repeat for several drives, in the order of their `--gt`.
    #[arg(long, required = true)]
    pub predictions: Vec<PathBuf>,
    /// Ground truth: MapTR's `{"GTs": [...]}` file, or our layout (e.g. a scenario's
    /// `ground_truth.json`; `confidence_level` optional). Repeat for several drives.
    #[arg(long, required = true)]
    pub gt: Vec<PathBuf>,
    /// Chamfer thresholds, metres.
    #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 1.5])]
    pub thresholds_m: Vec<f64>,
    /// Write the report here as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also write both inputs into this folder as MapTR's `nuscmap_results.json` and a
    /// `{"GTs": [...]}` file `map_anns.json`, for MapTR's own evaluator.
    #[arg(long)]
    pub write_maptr: Option<PathBuf>,
}

/// Score and print.
///
/// # Errors
/// Unreadable or malformed input files, or the report cannot be written.
pub fn run(args: &Args) -> Result<()> {
    check_thresholds(&args.thresholds_m)?;
    if args.predictions.len() != args.gt.len() {
        return Err(BadArgument(format!(
            "{} --predictions files but {} --gt files: give them in pairs, one of each per drive",
            args.predictions.len(),
            args.gt.len()
        ))
        .into());
    }
    let (predictions, gt) = read_pairs(&args.predictions, &args.gt)?;
    let report = evaluate_at(&predictions.samples, &gt.samples, &args.thresholds_m);
    print!("{}", format_report(&report));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text).with_context(|| path.display().to_string())?;
    }
    if let Some(dir) = &args.write_maptr {
        std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
        write_maptr_pair(
            &predictions.samples,
            &gt.samples,
            predictions.meta,
            &dir.join(MAPTR_RESULTS_FILE),
            &dir.join(MAPTR_GT_FILE),
        )?;
    }
    Ok(())
}

/// Every pair's files read (bad input, exit 2, when one cannot be read or scored) and, for more
/// than one pair, pooled with their tokens prefixed by the pair's index.
fn read_pairs(predictions: &[PathBuf], gt: &[PathBuf]) -> Result<(LoadedFile, LoadedFile)> {
    let read = |p: &PathBuf| read_file(p).map_err(|e| BadArgument(e.to_string()));
    if let ([p], [g]) = (predictions, gt) {
        return Ok((read(p)?, read(g)?));
    }
    let mut merged: Option<(LoadedFile, LoadedFile)> = None;
    for (i, (p, g)) in predictions.iter().zip(gt).enumerate() {
        let (p, g) = (read(p)?, read(g)?);
        let (mp, mg) = merged.get_or_insert_with(|| {
            let empty = |f: &LoadedFile| LoadedFile {
                layout: f.layout,
                meta: f.meta.clone(),
                samples: SampleSet::new(),
            };
            (empty(&p), empty(&g))
        });
        for (from, into) in [(p.samples, &mut mp.samples), (g.samples, &mut mg.samples)] {
            for (token, vectors) in from {
                into.insert(format!("{i}/{token}"), vectors);
            }
        }
    }
    merged.ok_or_else(|| BadArgument("no --predictions / --gt pair given".into()).into())
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

/// Thresholds must be finite and in (0, 100) m: NaN or a negative threshold matches nothing and
/// silently scores 0, and one at or above [`NO_OVERLAP_DISTANCE_M`] would let pairs whose
/// buffers never intersect match.
fn check_thresholds(thresholds_m: &[f64]) -> Result<(), BadArgument> {
    if thresholds_m.is_empty() {
        return Err(BadArgument(
            "--thresholds-m needs at least one threshold".into(),
        ));
    }
    match thresholds_m
        .iter()
        .find(|t| !(**t > 0.0 && **t < NO_OVERLAP_DISTANCE_M))
    {
        Some(t) => Err(BadArgument(format!(
            "--thresholds-m {t} must be in (0, {NO_OVERLAP_DISTANCE_M}) m"
        ))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::check_thresholds;

    #[test]
    fn thresholds_that_score_silently_wrong_are_refused() {
        assert!(check_thresholds(&[0.5, 1.0, 1.5]).is_ok());
        for bad in [
            vec![],
            vec![f64::NAN],
            vec![0.5, -1.0],
            vec![0.0],
            vec![100.0],
            vec![f64::INFINITY],
        ] {
            assert!(check_thresholds(&bad).is_err(), "{bad:?}");
        }
        assert_eq!(
            check_thresholds(&[1.0, f64::NAN]).unwrap_err().to_string(),
            "--thresholds-m NaN must be in (0, 100) m"
        );
    }
}
