//! The LSTM surrogate (Jiang et al. 2024, section 2.3.2): training sets from design points,
//! training through the embedded PyTorch trainer, and evaluation of the exported ONNX model
//! through ONNX Runtime.
//!
//! * [`dataset`]: [`TrainingSet`] (design points x 8,760 h) written as `.npy` + `dataset.json`.
//! * [`train()`]: runs `python -m bemcal_train` (LSTM, lookback 3, 2 x 128, ReLU, linear head),
//!   which writes the ONNX graphs and `surrogate.json` ([`SurrogateMeta`]).
//! * [`surrogate`]: [`Surrogate::load`] and [`Evaluator`], the per-proposal hot path.
//! * [`pretrained`]: the family's pretrained network folded onto one building, the warm start
//!   of its surrogate.
//! * [`schedule`]: the building's schedule as hourly inputs, for a surrogate folded from the
//!   pretrained network.
//! * [`predict`]: CSV output of an evaluation.
//! * [`parity`]: the trainer's PyTorch outputs, against which every trained surrogate's graphs
//!   are checked.
#![deny(missing_docs)]

pub mod dataset;
pub mod parity;
pub mod predict;
pub mod pretrained;
pub mod schedule;
pub mod surrogate;
pub mod train;

pub use dataset::{DatasetError, DatasetMeta, ParamSpec, Split, TrainingSet};
pub use parity::{ParityFixture, PARITY_FILE, PARITY_TOLERANCE};
pub use surrogate::{
    ort_environment, ort_library_path, Evaluator, Precision, Surrogate, SurrogateError,
    SurrogateMeta,
};
pub use train::{train, LrSchedule, TimeFeatures, TrainOptions, TrainReport, WEIGHTS_FILE};
