import sys

from hframe_id.cli import main

sys.exit(main())
