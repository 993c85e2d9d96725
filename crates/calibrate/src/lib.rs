//! The calibration pipeline on one machine: project files, design points, training, chains, validation and the summary.
