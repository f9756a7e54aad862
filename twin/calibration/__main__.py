"""``python -m twin.calibration [--dem] [--fast] [--out PATH]``: regenerate a calibration."""

import sys

from .table import main

sys.exit(main())
