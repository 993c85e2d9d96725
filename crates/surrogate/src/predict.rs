//! Writing surrogate predictions as CSV: `timestamp,<output>...`, one row per hour, ISO 8601
//! local standard time, hour beginning.

use std::io::Write;
use std::path::Path;

use ndarray::ArrayView2;

/// Hour-beginning ISO 8601 timestamps for EPW `(month, day, hour 1..=24)` rows in `year`
/// (EPW hour 1 covers 00:00-01:00, so it becomes `T00:00:00`; a year from another month dates
/// the months before it in the next year). Pure.
pub fn hour_beginning_timestamps(
    year: bemcal_weather::grid::GridYear,
    rows: impl IntoIterator<Item = (u32, u32, u32)>,
) -> Vec<String> {
    rows.into_iter()
        .map(|(m, d, h)| {
            let y = year.year_of_month(m);
            format!("{y:04}-{m:02}-{d:02}T{:02}:00:00", h.saturating_sub(1))
        })
        .collect()
}

/// Writes `timestamp,<names>...` and one row per hour of `values` (`[n_hours, n_outputs]`).
pub fn write_csv(
    path: &Path,
    timestamps: &[String],
    names: &[String],
    values: ArrayView2<'_, f32>,
) -> std::io::Result<()> {
    if timestamps.len() != values.nrows() || names.len() != values.ncols() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "{} timestamps and {} names for values of shape {:?}",
                timestamps.len(),
                names.len(),
                values.dim()
            ),
        ));
    }
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(w, "timestamp,{}", names.join(","))?;
    for (ts, row) in timestamps.iter().zip(values.rows()) {
        write!(w, "{ts}")?;
        for v in row {
            write!(w, ",{v}")?;
        }
        writeln!(w)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epw_hour_one_is_midnight_hour_beginning() {
        let ts = hour_beginning_timestamps(2021.into(), [(1, 1, 1), (12, 31, 24)]);
        assert_eq!(ts, ["2021-01-01T00:00:00", "2021-12-31T23:00:00"]);
    }
}
