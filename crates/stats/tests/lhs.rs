//! Latin hypercube: stratification, maximin, constraint repair, determinism.

use bemcal_stats::lhs::{self, LhsOptions, PairConstraint};
use bemcal_stats::{StatsError, Triangular};

fn tri(a: f64, c: f64, b: f64) -> Triangular {
    Triangular::new(a, c, b).unwrap()
}

fn assert_one_per_stratum(design: &lhs::Design) {
    let n = design.points.len();
    for k in 0..design.points[0].len() {
        let mut seen = vec![0; n];
        for row in &design.probabilities {
            seen[lhs::stratum(row[k], n)] += 1;
        }
        assert!(seen.iter().all(|&c| c == 1), "column {k}: {seen:?}");
    }
}

#[test]
fn stratified_and_deterministic() {
    let priors = [
        tri(0.0, 1.0, 4.0),
        tri(10.0, 20.0, 20.0),
        tri(-1.0, 0.0, 1.0),
    ];
    let opts = LhsOptions::default();
    let a = lhs::latin_hypercube(&priors, 37, 5, &opts).unwrap();
    assert_one_per_stratum(&a);
    for row in &a.points {
        for (x, p) in row.iter().zip(&priors) {
            assert!(p.contains(*x));
        }
    }
    // Values are the inverse CDF of the probabilities.
    assert_eq!(a.points[3][1], priors[1].quantile(a.probabilities[3][1]));
    assert_eq!(a, lhs::latin_hypercube(&priors, 37, 5, &opts).unwrap());
    assert_ne!(
        a.points,
        lhs::latin_hypercube(&priors, 37, 6, &opts).unwrap().points
    );
}

#[test]
fn maximin_does_not_reduce_min_distance() {
    let priors = vec![tri(0.0, 0.5, 1.0); 4];
    let plain = lhs::latin_hypercube(&priors, 40, 3, &LhsOptions::default()).unwrap();
    let opts = LhsOptions {
        maximin_iterations: 2000,
        ..LhsOptions::default()
    };
    let better = lhs::latin_hypercube(&priors, 40, 3, &opts).unwrap();
    assert_one_per_stratum(&better);
    assert!(better.maximin_swaps > 0);
    assert!(
        better.min_distance > plain.min_distance,
        "{} vs {}",
        better.min_distance,
        plain.min_distance
    );
}

#[test]
fn set_point_constraints_repaired_by_swaps() {
    // 0 heating set-point, 1 cooling set-point, 2 chilled water, 3 supply air.
    let priors = [
        tri(18.0, 21.0, 24.0),
        tri(21.0, 24.0, 27.0),
        tri(5.0, 7.0, 12.0),
        tri(10.0, 13.0, 16.0),
    ];
    let cons = vec![
        PairConstraint::new(0, 1, 0.0),
        PairConstraint::new(2, 3, -3.0),
    ];
    let opts = LhsOptions {
        maximin_iterations: 500,
        constraints: cons.clone(),
    };
    let d = lhs::latin_hypercube(&priors, 60, 11, &opts).unwrap();
    assert!(d.repair.rows_infeasible_before > 0, "{:?}", d.repair);
    assert!(d.repair.swaps > 0);
    assert_eq!(d.repair.resampled_in_stratum, 0);
    assert_eq!(d.repair.resampled_outside_stratum, 0);
    assert_one_per_stratum(&d);
    for row in &d.points {
        assert!(cons.iter().all(|c| c.holds(row)), "{row:?}");
    }
    assert_eq!(d, lhs::latin_hypercube(&priors, 60, 11, &opts).unwrap());
}

#[test]
fn tight_constraint_needs_resampling() {
    // x0 - x1 <= -8 on two U-like priors over [0, 10]: most strata pairs cannot satisfy it.
    let priors = [tri(0.0, 0.0, 10.0), tri(0.0, 10.0, 10.0)];
    let cons = vec![PairConstraint::new(0, 1, -8.0)];
    let opts = LhsOptions {
        maximin_iterations: 0,
        constraints: cons.clone(),
    };
    let d = lhs::latin_hypercube(&priors, 20, 2, &opts).unwrap();
    assert!(d.repair.resampled_in_stratum + d.repair.resampled_outside_stratum > 0);
    for row in &d.points {
        assert!(cons[0].holds(row), "{row:?}");
        assert!(priors[0].contains(row[0]) && priors[1].contains(row[1]));
    }
}

#[test]
fn impossible_constraint_is_an_error() {
    let priors = [tri(10.0, 11.0, 12.0), tri(0.0, 1.0, 2.0)];
    let opts = LhsOptions {
        maximin_iterations: 0,
        constraints: vec![PairConstraint::new(0, 1, 0.0)],
    };
    match lhs::latin_hypercube(&priors, 5, 1, &opts) {
        Err(StatsError::InfeasibleDesign { rows }) => assert_eq!(rows, vec![0, 1, 2, 3, 4]),
        other => panic!("{other:?}"),
    }
    let bad = LhsOptions {
        maximin_iterations: 0,
        constraints: vec![PairConstraint::new(0, 2, 0.0)],
    };
    assert!(lhs::latin_hypercube(&priors, 5, 1, &bad).is_err());
}
