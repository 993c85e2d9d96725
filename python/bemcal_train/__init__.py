"""bemcal_train: trains the LSTM surrogate of bemcal and exports it to ONNX.

Reference: Jiang et al., Energy & Buildings 323 (2024) 114755, section 2.3.2 and Table 3:
an LSTM with lookback 3, two layers of 128 units, a ReLU after the LSTM and a fully connected
head with one output per meter; Adam with learning rate 1e-3.

Run as ``python -m bemcal_train --dataset DIR --out DIR``. The dataset directory is written by the
Rust crate ``bemcal-surrogate`` (``TrainingSet::write``); see ``data.py`` for the format.
"""

FORMAT = "bemcal-surrogate"
FORMAT_VERSION = 1
DATASET_FORMAT_VERSION = 1
LOOKBACK = 3
