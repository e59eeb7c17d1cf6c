"""`python -m mech2spice.reports NAME ...`: the same as `mech2spice report NAME ...`."""
import sys

from .cli import main

sys.exit(main())
