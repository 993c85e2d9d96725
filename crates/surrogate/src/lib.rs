//! The LSTM surrogate: training sets from design points, and evaluation of the exported ONNX model through ONNX Runtime.
