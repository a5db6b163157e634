import sys

from hframe_id.cli import main

if __name__ == "__main__":
    sys.exit(main())
