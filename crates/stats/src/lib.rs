//! Pure numerics of Bayesian calibration: triangular priors, Latin hypercube designs, Metropolis-Hastings chains, convergence diagnostics and ASHRAE Guideline 14 metrics.
