"""``python -m twin.surrogate --generate --train``."""

import sys

from twin.surrogate import main  # through the package, so pickles name twin.surrogate.Surrogate

sys.exit(main())
