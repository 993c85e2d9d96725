//! Retrofit measures' savings (`bemcal savings`, `summary.json`'s `savings`): a table per
//! measure (each output's saving under each weather, its intervals, the saving at the estimate,
//! what drives the width, the warnings) and the monthly savings of the metered outputs.

use std::fmt::Write as _;

use bemcal_calibrate::measures::{MeasureSavings, SavingsWeather};
use bemcal_calibrate::Summary;

use super::{esc, f, figure};
use crate::error::ReportError;
use crate::plots;

/// The section, or nothing before `bemcal savings` ran.
pub(super) fn savings_section(s: &Summary) -> Result<String, ReportError> {
    let Some(r) = &s.savings else {
        return Ok(String::new());
    };
    let mut h = String::new();
    let _ =
        write!(
        h,
        "<h2 id=\"savings\">Savings of retrofit measures</h2><p class=\"sub\">EnergyPlus at {} \
         posterior draws ({}) with and without each measure; a saving is positive when the \
         measure saves. {}</p>",
        r.draws,
        esc(&r.draws_file),
        r.notes.iter().map(|n| esc(n)).collect::<Vec<_>>().join(" &middot; ")
    );
    for m in &r.measures {
        measure(&mut h, s, m)?;
    }
    Ok(h)
}

/// One measure's table and its monthly figures.
fn measure(h: &mut String, s: &Summary, m: &MeasureSavings) -> Result<(), ReportError> {
    let _ = write!(
        h,
        "<h3>{}</h3><p class=\"sub\">{} &middot; {}</p>",
        esc(&m.measure),
        esc(&m.edits.join(", ")),
        esc(&m.method_note)
    );
    for n in m.notes.iter().chain(&m.failed) {
        let _ = write!(h, "<p class=\"sub\">{}</p>", esc(n));
    }
    h.push_str(
        "<table><tr><th class=\"l\">output</th><th class=\"l\">weather</th><th>baseline kWh</th>\
         <th>saving kWh</th><th>50 % interval</th><th>90 % interval</th><th>%</th>\
         <th>at the estimate</th><th class=\"l\">driven by</th></tr>",
    );
    for o in &m.outputs {
        let s50 = o.savings_kwh.interval_50;
        let s90 = o.savings_kwh.interval_90;
        let drivers = o
            .drivers
            .iter()
            .take(2)
            .map(|d| format!("{} ({:.0} %)", esc(&d.parameter), 100.0 * d.share))
            .collect::<Vec<_>>()
            .join(", ");
        let warning = o
            .warning
            .as_ref()
            .map(|w| format!("<br><span class=\"bad\">{}</span>", esc(w)))
            .unwrap_or_default();
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}{warning}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td>\
             <td>[{}, {}]</td><td>[{}, {}]</td><td>{}</td><td>{}</td><td class=\"l\">{}</td></tr>",
            esc(&o.output),
            o.weather.as_str(),
            f(o.baseline_kwh, 0),
            f(o.savings_kwh.median, 0),
            f(s50[0], 0),
            f(s50[1], 0),
            f(s90[0], 0),
            f(s90[1], 0),
            f(o.savings_percent.median, 1),
            f(o.at_estimate_kwh, 0),
            if drivers.is_empty() {
                "&ndash;".into()
            } else {
                drivers
            }
        );
    }
    h.push_str("</table>\n");
    let unidentified: std::collections::BTreeSet<String> = (m.outputs.iter())
        .flat_map(|o| &o.drivers)
        .filter(|d| d.width_ratio > 0.5)
        .map(|d| {
            format!(
                "{} (its 90 % interval {} of the prior's): {}",
                esc(&d.parameter),
                f(d.width_ratio, 2),
                esc(&d.would_narrow)
            )
        })
        .collect();
    for u in unidentified {
        let _ = write!(h, "<p class=\"sub\">Would narrow it: {u}</p>");
    }
    for o in m.outputs.iter().filter(|o| {
        o.weather == SavingsWeather::Calibration
            && s.outputs.contains(&o.output)
            && o.savings_kwh.interval_90 != [0.0, 0.0]
    }) {
        let svg = plots::monthly_savings(&o.monthly_kwh, "kWh saved")?;
        h.push_str(&figure(
            &svg,
            &format!(
                "{}: {} monthly savings, median (bar), 50 % (thick) and 90 % (thin) intervals",
                esc(&m.measure),
                esc(&o.output)
            ),
        ));
    }
    Ok(())
}
