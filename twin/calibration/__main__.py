"""``python -m twin.calibration [--map dem|mineralogy] [--from FILE] [--out PATH] ...``: as ``grindtwin calibrate``."""

import sys

from .calibrate import main

sys.exit(main())
