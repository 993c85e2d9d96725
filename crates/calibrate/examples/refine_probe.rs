//! Experiment for the surrogate-refinement idea (not part of the pipeline): simulate `K`
//! posterior draws of a finished calibration in EnergyPlus, add them to the design, retrain the
//! surrogate in place. Then compare the new surrogate at the estimate with EnergyPlus there.
//!
//!     refine_probe PROJECT.toml CALIBRATION_DIR K      (a copy of the folder: it is modified)
use bemcal_calibrate::pipeline::Calibration;
use bemcal_calibrate::project::Project;
use std::path::Path;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let k: usize = a[3].parse().unwrap();
    let project = Project::load(Path::new(&a[1])).unwrap();
    let cal = Calibration::load(project, Path::new(&a[2])).unwrap();
    let mut design = cal.design().unwrap();
    let n0 = design.points.len();
    let mut sims = vec![];
    for i in 0..n0 {
        sims.push(cal.simulate_point(i, &design.points[i]).unwrap().0);
    }
    // Posterior draws spread over the chains (draws.csv: chain,draw,<params>...,log_posterior).
    let text = std::fs::read_to_string(cal.out.join("draws.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let d = design.points[0].len();
    let step = rows.len() / k;
    let picks: Vec<Vec<f64>> = (0..k)
        .map(|j| rows[j * step + step / 2][2..2 + d].to_vec())
        .collect();
    eprintln!("{} columns, {} draws, {k} picks", header.len(), rows.len());
    let t = std::time::Instant::now();
    let results: Vec<(Vec<f64>, _)> = std::thread::scope(|s| {
        let hs: Vec<_> = picks
            .chunks(k.div_ceil(2))
            .enumerate()
            .map(|(c, ch)| {
                let cal = &cal;
                s.spawn(move || {
                    ch.iter()
                        .enumerate()
                        .filter_map(|(j, x)| {
                            match cal.simulate_point(n0 + c * k.div_ceil(2) + j, x) {
                                Ok((o, _)) => Some((x.clone(), o)),
                                Err(e) => {
                                    eprintln!("draw skipped: {e}");
                                    None
                                }
                            }
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        hs.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    eprintln!("{k} simulations in {:.0} s", t.elapsed().as_secs_f64());
    for (x, o) in results {
        design.points.push(x);
        sims.push(o);
    }
    cal.training_set(&design, &sims).unwrap();
    let _ = std::fs::remove_dir_all(cal.surrogate_dir());
    let t = std::time::Instant::now();
    cal.train().unwrap();
    eprintln!(
        "retrained on {} points in {:.0} s",
        design.points.len(),
        t.elapsed().as_secs_f64()
    );
}
