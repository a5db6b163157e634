"""``python -m hframe_id.fleet.studies``."""

import sys

from hframe_id.fleet.studies.cli import main

sys.exit(main())
