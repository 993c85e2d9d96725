//! Runs a manifest's missing cases with EnergyPlus and records each in the corpus folder.
//!
//! Orchestration only: the cases come from [`crate::draw`], the folder from [`crate::store`].
//! A case EnergyPlus refuses (or that runs past the runner's time limit) is recorded as a
//! failure with its reason and the corpus goes on; only an error of the folder itself stops it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use bemcal_energyplus::{Model, Runner};
use bemcal_weather::{Calendar, Epw, HourlyFeatures};

use crate::draw::{case, Case};
use crate::manifest::Manifest;
use crate::store::{CorpusInfo, Failed, Finished, Store, WEATHER_FEATURES};
use crate::Error;

/// The outputs every case records (a generated building's meters).
pub const OUTPUTS: [&str; 5] = [
    "heating_kwh",
    "cooling_kwh",
    "electricity_kwh",
    "lighting_kwh",
    "equipment_kwh",
];

/// Which cases to run, and how.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Cases `0..cases` of the manifest (at most its `cases`).
    pub cases: usize,
    /// EnergyPlus runs at once.
    pub parallel: usize,
}

/// What a build did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    /// Cases finished now.
    pub finished: usize,
    /// Cases EnergyPlus refused now.
    pub failed: usize,
    /// Cases settled before (skipped).
    pub settled_before: usize,
    /// EnergyPlus seconds of the cases finished now.
    pub simulation_seconds: f64,
    /// Wall time, s.
    pub wall_seconds: f64,
}

/// The corpus's description.
pub fn info() -> CorpusInfo {
    CorpusInfo {
        format: crate::store::FORMAT_VERSION,
        simulation_revision: bemcal_energyplus::SIMULATION_REVISION,
        outputs: OUTPUTS.iter().map(|s| s.to_string()).collect(),
        output_unit: "Wh/m2 per hour".into(),
        weather_features: WEATHER_FEATURES.iter().map(|s| s.to_string()).collect(),
    }
}

/// Simulates the manifest's cases `0..settings.cases` missing from `dir`; `weather` maps each
/// climate's name to its EPW. `progress` hears one line per settled case.
pub fn build(
    manifest: &Manifest,
    weather: &BTreeMap<String, PathBuf>,
    runner: &Runner,
    dir: &Path,
    settings: &Settings,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Outcome, Error> {
    let t0 = Instant::now();
    let store = Store::open(dir, &info())?;
    let calendar = Calendar::new(manifest.year, manifest.holidays.clone());
    for (name, path) in weather {
        let epw = Epw::read(path).map_err(|e| Error::Io {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let f = HourlyFeatures::from_epw(&epw, &calendar);
        let rows: Vec<[f64; 5]> = (0..f.len()).map(|t| f.row(t)).collect();
        store.write_weather(name, &rows)?;
    }
    let cases: Vec<Case> = (0..settings.cases.min(manifest.cases))
        .map(|i| case(manifest, i))
        .collect();
    let pending: Vec<&Case> = cases.iter().filter(|c| !store.settled(&c.key())).collect();
    let mut outcome = Outcome {
        settled_before: cases.len() - pending.len(),
        ..Outcome::default()
    };
    let total = pending.len();
    let store = Mutex::new(store);
    let tally = Mutex::new((0usize, 0usize, 0.0f64));
    // Threads take the pending cases in index order (not rayon's halves): a corpus stopped at
    // any moment holds a prefix of the sequence, give or take the cases in flight.
    let next = AtomicUsize::new(0);
    let work = || -> Result<(), Error> {
        let run = || -> Result<(), Error> {
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(c) = pending.get(i) else {
                    return Ok(());
                };
                let settled = simulate_case(c, weather, runner, dir)?;
                let mut tally = tally.lock().expect("not poisoned");
                let mut store = store.lock().expect("not poisoned");
                let line = match settled {
                    Settled::Finished(f, series) => {
                        tally.2 += f.seconds;
                        tally.0 += 1;
                        let line = format!("{:.1} s", f.seconds);
                        store.finish(f, &series)?;
                        line
                    }
                    Settled::Failed(f) => {
                        tally.1 += 1;
                        let line = format!("failed: {}", bemcal_excerpt::excerpt(&f.reason, 160));
                        store.fail(f)?;
                        line
                    }
                };
                progress(&format!(
                    "case {} ({}/{total}; {} {}, {} storeys, {:?}, {:?}): {line}",
                    c.index,
                    tally.0 + tally.1,
                    c.climate,
                    c.spec.name,
                    c.spec.storeys,
                    c.spec.zoning,
                    c.spec.hvac,
                ));
            }
        };
        // An error of the folder itself stops the other threads at their next case.
        run().inspect_err(|_| next.store(usize::MAX / 2, Ordering::Relaxed))
    };
    std::thread::scope(|scope| {
        let threads: Vec<_> = (0..settings.parallel.max(1))
            .map(|_| scope.spawn(work))
            .collect();
        threads
            .into_iter()
            .map(|t| t.join().expect("a corpus thread panicked"))
            .collect::<Result<Vec<()>, Error>>()
    })?;
    let (finished, failed, seconds) = *tally.lock().expect("not poisoned");
    outcome.finished = finished;
    outcome.failed = failed;
    outcome.simulation_seconds = seconds;
    outcome.wall_seconds = t0.elapsed().as_secs_f64();
    Ok(outcome)
}

enum Settled {
    Finished(Finished, Vec<Vec<f64>>),
    Failed(Failed),
}

/// EnergyPlus for one case in `dir/runs/<key>` (removed after), its meters per m2 of floor.
fn simulate_case(
    c: &Case,
    weather: &BTreeMap<String, PathBuf>,
    runner: &Runner,
    dir: &Path,
) -> Result<Settled, Error> {
    let key = c.key();
    let model = Model::generated(c.spec.clone());
    let run_dir = dir.join("runs").join(&key);
    if run_dir.exists() {
        std::fs::remove_dir_all(&run_dir).map_err(crate::io_err(&run_dir))?;
    }
    let epw = &weather[&c.climate];
    let run = model
        .instantiate(&c.values, runner.idd())
        .and_then(|idf| runner.run(&idf, epw, model.outputs(), &run_dir));
    let _ = std::fs::remove_dir_all(&run_dir);
    let r = match run {
        Ok(r) => r,
        Err(e @ bemcal_energyplus::Error::Io { .. })
        | Err(e @ bemcal_energyplus::Error::EngineNotFound(_)) => return Err(e.into()),
        Err(e) => {
            return Ok(Settled::Failed(Failed {
                key,
                case: c.clone(),
                reason: e.to_string(),
            }))
        }
    };
    let area = c.spec.floor_area_m2();
    let series = OUTPUTS
        .iter()
        .map(|name| {
            let s = r.outputs.get(name).expect("a generated building's outputs");
            s.iter().map(|kwh| kwh * 1000.0 / area).collect()
        })
        .collect();
    Ok(Settled::Finished(
        Finished {
            key,
            case: c.clone(),
            floor_area_m2: area,
            seconds: r.seconds,
            notes: r.notes,
        },
        series,
    ))
}
