"""bemcal: Bayesian calibration of EnergyPlus building energy models against hourly meters.

The Python side of bemcal. The calibration itself runs in the ``bemcal`` binary (installed
beside this module by ``pip install bemcal``); this module starts it and reads what it wrote:

>>> import bemcal
>>> result = bemcal.calibrate("quick.toml", out="calibration", workers=2)   # doctest: +SKIP
>>> result.posterior                      # arviz.InferenceData                # doctest: +SKIP
>>> result.metrics                        # Guideline 14, pandas DataFrame     # doctest: +SKIP
>>> result.estimate                       # {parameter: value}                 # doctest: +SKIP
>>> result.model_path                     # the calibrated EnergyPlus model    # doctest: +SKIP

``bemcal.load(out_dir)`` reads a finished output folder (a local ``bemcal calibrate --out`` or
``bemcal results``), without running anything.
"""

from ._binary import BemcalError, binary, run
from ._calibrate import calibrate
from .results import Calibration, load

__all__ = ["BemcalError", "Calibration", "binary", "calibrate", "load", "run", "__version__"]


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("bemcal")
    except Exception:  # running from a repository checkout, not an installed wheel
        return "0+repository"


__version__ = _version()
