"""``python -m studies.fleet``."""

import sys

from studies.fleet.cli import main

sys.exit(main())
