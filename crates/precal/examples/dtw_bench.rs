//! DTW pairwise-matrix benchmark (compare with `python/tools/dtw_bench.py`, same data).
//!
//! Data: BDG2 electricity of 238 buildings (`../shared/data/bdg2/electricity_subset_238bldgs_from_lstm-bgd2.csv`
//! or the path given as the first argument); per building its 2016 daily profiles (raw kWh,
//! 24 values per day), days with any NaN or fewer than 24 hours skipped. The "one building-year"
//! case is the first building with at least 365 complete days.
//!
//! ```sh
//! cargo run --release -p bemcal-precal --example dtw_bench -- [CSV] [BAND]
//! ```

use std::collections::BTreeMap;
use std::time::Instant;

use bemcal_precal::dtw::{distance_matrix, Band};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).cloned().unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/data/bdg2/electricity_subset_238bldgs_from_lstm-bgd2.csv"
        )
        .to_string()
    });
    let band = Band::new(args.get(2).map_or(2, |b| b.parse().expect("band")));
    let t0 = Instant::now();
    let mut rdr = csv::Reader::from_path(&path).expect("BDG2 CSV");
    let nb = rdr.headers().unwrap().len() - 1;
    // day -> per building 24 values (NaN for missing)
    let mut days: BTreeMap<String, Vec<Vec<f64>>> = BTreeMap::new();
    for rec in rdr.records() {
        let rec = rec.unwrap();
        let ts = &rec[0];
        if !ts.starts_with("2016") {
            continue;
        }
        let d = days
            .entry(ts[..10].to_string())
            .or_insert_with(|| vec![Vec::with_capacity(24); nb]);
        for (b, v) in d.iter_mut().enumerate() {
            v.push(rec[b + 1].trim().parse::<f64>().unwrap_or(f64::NAN));
        }
    }
    let mut per_building: Vec<Vec<Vec<f64>>> = vec![Vec::new(); nb];
    for d in days.values() {
        for (b, v) in d.iter().enumerate() {
            if v.len() == 24 && v.iter().all(|x| x.is_finite()) {
                per_building[b].push(v.clone());
            }
        }
    }
    let n_profiles: usize = per_building.iter().map(Vec::len).sum();
    println!(
        "loaded {nb} buildings, {n_profiles} complete 2016 days in {:.0} ms; band |i-j| <= {:?} (dtaidistance window {:?}); rayon threads {}",
        t0.elapsed().as_secs_f64() * 1e3,
        band.max_shift.unwrap(),
        band.dtaidistance_window().unwrap(),
        rayon::current_num_threads()
    );

    let one = per_building
        .iter()
        .position(|p| p.len() >= 365)
        .expect("a building with >= 365 complete days");
    let series = &per_building[one];
    let time = |f: &dyn Fn() -> f64, reps: usize| -> (f64, f64) {
        let mut best = f64::INFINITY;
        let mut check = 0.0;
        for _ in 0..reps {
            let t = Instant::now();
            check = f();
            best = best.min(t.elapsed().as_secs_f64());
        }
        (best * 1e3, check)
    };
    let one_year = || distance_matrix(series, band).data.iter().sum::<f64>() / 2.0;
    let all = || {
        per_building
            .iter()
            .filter(|p| p.len() >= 2)
            .map(|p| distance_matrix(p, band).data.iter().sum::<f64>() / 2.0)
            .sum::<f64>()
    };
    let (ms1, c1) = time(&one_year, 20);
    println!(
        "rust one building-year (building #{one}, {} x {}): {ms1:.3} ms (best of 20), sum of upper triangle {c1:.6}",
        series.len(),
        series.len()
    );
    let (ms_all, c_all) = time(&all, 3);
    println!("rust all {nb} buildings: {ms_all:.1} ms (best of 3), sum {c_all:.6}");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let (ms1s, _) = pool.install(|| time(&one_year, 10));
    let (ms_alls, _) = pool.install(|| time(&all, 2));
    println!("rust 1 thread: one building-year {ms1s:.3} ms, all buildings {ms_alls:.1} ms");
}
