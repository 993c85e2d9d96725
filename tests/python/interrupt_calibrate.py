"""``bemcal.calibrate`` interrupted (KeyboardInterrupt, as a notebook's stop button raises it)
once its local workers start: the call raises, and prints the folder it was writing to."""

import sys

import bemcal


def stop_at_workers(line: str) -> None:
    if "starting 2 workers" in line:
        raise KeyboardInterrupt


try:
    bemcal.calibrate(sys.argv[1], sys.argv[2], workers=2, echo=stop_at_workers)
except KeyboardInterrupt:
    print("interrupted")
else:
    sys.exit("the calibration was not interrupted")
