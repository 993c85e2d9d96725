//! `report.html` for a calibration: one self-contained HTML file (inline SVG figures, inline
//! CSS, no external resources) that people can read.
//!
//! It shows, from a folder written by `bemcal calibrate --out DIR`:
//! warnings (R-hat, ESS, uninformed parameters, correlated pairs, acceptance, G14 failures);
//! the initial and calibrated ASHRAE Guideline 14 metrics (the reference's Table 5); the
//! estimated parameters with prior and posterior intervals (Table 4); prior vs posterior per
//! parameter (Fig. 10); trace and rank plots per parameter; hourly measured vs calibrated with
//! the posterior predictive band and the meter's gaps, as a daily year view plus one week per
//! season at full resolution (Fig. 11); timings and acceptance rates. With a pre-calibration
//! folder (`bemcal precalibrate --out PDIR`) it adds the daily profile clusters (Fig. 4), the
//! per-hour schedule boxes (Fig. 5) and the merged intervals (Fig. 6). With a synthetic run's
//! hidden truth (`bemcal synthesize --truth FILE`) it adds the truth beside the posterior, each
//! miss explained ([`truth`]).
//!
//! Layout: [`io`] does all file reading and writing; [`analysis`], [`informed`], [`recovery`], [`truth`],
//! [`plots`] (data in, SVG out) and [`html`] are pure.
#![deny(missing_docs)]

pub mod analysis;
mod error;
pub mod html;
pub mod informed;
pub mod io;
pub mod modes;
pub mod plots;
pub mod portfolio;
pub mod recovery;
pub mod truth;

pub use error::{PlotError, ReportError};

use std::path::{Path, PathBuf};

/// Builds the report HTML for already-loaded data (pure).
pub fn render(
    cal: &io::CalibrationData,
    precal: Option<&io::PrecalData>,
) -> Result<String, ReportError> {
    html::build(cal, precal)
}

/// Reads `calibration_dir` (and `precal_dir`, if given) and writes
/// `calibration_dir/report.html`; returns its path.
pub fn write_report(
    calibration_dir: &Path,
    precal_dir: Option<&Path>,
) -> Result<PathBuf, ReportError> {
    Ok(write_report_with_truth(calibration_dir, precal_dir, None)?.path)
}

/// What [`write_report_with_truth`] wrote.
#[derive(Debug, Clone)]
pub struct Written {
    /// `report.html`.
    pub path: PathBuf,
    /// The truth beside the posterior, when a truth file was given.
    pub recovery: Option<recovery::Recovery>,
}

/// [`write_report`], and with `truth_file` (a synthetic run's hidden true values) the truth
/// beside the posterior in the report and in what is returned. A truth file that names none of
/// the calibrated parameters is an error.
pub fn write_report_with_truth(
    calibration_dir: &Path,
    precal_dir: Option<&Path>,
    truth_file: Option<&Path>,
) -> Result<Written, ReportError> {
    let mut cal = io::read_calibration(calibration_dir)?;
    let pre = precal_dir.map(io::read_precal).transpose()?;
    if let Some(f) = truth_file {
        let values = io::read_truth(f)?;
        let recovery = truth::recovery(&values, &cal.summary, &cal.draws);
        if recovery.rows.is_empty() {
            let names = |v: Vec<&str>| match v.len() {
                0 => "none".to_string(),
                n if n <= 3 => v.join(", "),
                n => format!("{}, ... ({n})", v[..3].join(", ")),
            };
            return Err(ReportError::Parse {
                path: f.to_path_buf(),
                msg: format!(
                    "names none of the calibrated parameters ({}); it names {}",
                    names(recovery.without_truth.iter().map(String::as_str).collect()),
                    names(values.keys().map(String::as_str).collect())
                ),
            });
        }
        cal.truth = Some(recovery);
    }
    let text = render(&cal, pre.as_ref())?;
    let path = calibration_dir.join("report.html");
    io::write_html(&path, &text)?;
    Ok(Written {
        path,
        recovery: cal.truth,
    })
}
