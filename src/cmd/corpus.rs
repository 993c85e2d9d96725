//! `bemcal corpus`: EnergyPlus years of the building family for the pretrained surrogate.

use std::collections::BTreeMap;
use std::path::PathBuf;

use bemcal_corpus::manifest::Manifest;

use super::common;

/// Simulate a corpus manifest's cases (generated buildings x climates x population draws of
/// their parameters) into a corpus folder; a rerun continues where the last one stopped.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The corpus manifest (TOML; corpus/family.toml is the family's).
    pub manifest: PathBuf,
    /// The corpus folder (created; keep it outside the work tree while it grows).
    #[arg(long)]
    pub out: PathBuf,
    /// Simulate only the first N cases (a corpus of N is the first N of a larger one).
    #[arg(long)]
    pub cases: Option<usize>,
    /// EnergyPlus runs at once.
    #[arg(long, default_value_t = 2)]
    pub parallel: usize,
    /// Print what the cases are and which are settled; simulate nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let manifest = Manifest::load(&a.manifest)?;
    let cases = a.cases.unwrap_or(manifest.cases).min(manifest.cases);
    let bundled = |file: &str| -> Result<PathBuf, bemcal_corpus::Error> {
        common::resolve_weather_ref(&format!("bundled:{file}")).map_err(|e| {
            bemcal_corpus::Error::Io {
                path: file.into(),
                message: format!("{e:#}"),
            }
        })
    };
    let mut weather = BTreeMap::new();
    for c in &manifest.climates {
        let path = manifest.weather_path(c, &a.manifest, &bundled)?;
        anyhow::ensure!(
            path.is_file(),
            "{}: climate {:?}: no weather file at {}",
            a.manifest.display(),
            c.name,
            path.display()
        );
        weather.insert(c.name.clone(), path);
    }
    if a.dry_run {
        for i in 0..cases {
            let c = bemcal_corpus::draw::case(&manifest, i);
            println!(
                "{i:5} {} building {} point {} {:12} {} storeys {:?} {:?} {:?} wwr {} {} parameters",
                c.key(),
                c.building,
                c.point,
                c.climate,
                c.spec.storeys,
                c.spec.footprint_m,
                c.spec.zoning,
                c.spec.hvac,
                c.spec.window_to_wall,
                c.values.len()
            );
        }
        return Ok(());
    }
    let runner = common::runner()?;
    let settings = bemcal_corpus::build::Settings {
        cases,
        parallel: a.parallel,
    };
    let o = bemcal_corpus::build::build(
        &manifest,
        &weather,
        &runner,
        &a.out,
        &settings,
        &|m: &str| eprintln!("{m}"),
    )?;
    println!(
        "{} cases: {} settled before, {} finished now, {} failed now (recorded); {:.0} s EnergyPlus, {:.0} s wall; corpus in {}",
        cases,
        o.settled_before,
        o.finished,
        o.failed,
        o.simulation_seconds,
        o.wall_seconds,
        a.out.display()
    );
    Ok(())
}
