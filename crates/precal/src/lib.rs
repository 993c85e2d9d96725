//! Pre-calibration: meter ingestion, base-load disaggregation, DTW day-type clustering and informative schedule priors.
