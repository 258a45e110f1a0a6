"""``python -m tsid_fmu.build``: build FMUs from the Modelica models in ``models/``."""

import sys

from tsid_fmu.build import main

if __name__ == "__main__":
    sys.exit(main())
