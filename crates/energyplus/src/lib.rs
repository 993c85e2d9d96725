//! EnergyPlus 25.2: engine discovery, isolated runs, hourly meter output, and parametric building models with named calibration parameters.
