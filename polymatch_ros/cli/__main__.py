"""`python -m polymatch_ros.cli` = `polymatch`."""

import sys

from . import main

sys.exit(main())
