//! The dialect of a meters or bills file as a spreadsheet wrote it: its field separator, and
//! decimal commas where the separator is not a comma. Pure: no I/O.

/// The meters file's field separator, from its header line: a comma where the line has one,
/// else a semicolon or a tab where it has one (the exports of spreadsheets and loggers set to a
/// locale whose decimal mark is the comma), else a comma.
pub(crate) fn sniff_delimiter(text: &str) -> u8 {
    let header = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
    if header.contains(',') {
        b','
    } else if header.contains(';') {
        b';'
    } else if header.contains('\t') {
        b'\t'
    } else {
        b','
    }
}

/// `record` with a decimal comma read as a point in every field but the timestamp's
/// (`12,5` -> `12.5`) where that makes a number: a file whose fields a semicolon or a tab
/// separates ([`sniff_delimiter`]) writes its decimals so. The record keeps its position (the
/// line errors name).
pub(crate) fn decimal_points(record: &csv::StringRecord, ts_idx: usize) -> csv::StringRecord {
    let mut out: csv::StringRecord = record
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let pointed = f.replacen(',', ".", 1);
            let decimal = i != ts_idx
                && f.matches(',').count() == 1
                && !f.contains('.')
                && pointed.parse::<f64>().is_ok();
            if decimal {
                pointed
            } else {
                f.to_string()
            }
        })
        .collect();
    out.set_position(record.position().cloned());
    out
}
