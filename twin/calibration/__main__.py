"""``python -m twin.calibration [--map dem|mineralogy] [--from FILE] [--out PATH] ...``: as ``grindtwin calibrate``."""

import sys

from .calibrate import run

sys.exit(run())
