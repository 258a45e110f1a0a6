"""Run the command line with ``python -m tsid_fmu``."""

import sys

from tsid_fmu.cli import main

sys.exit(main())
