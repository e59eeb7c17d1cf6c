"""`python -m mech2spice.cli`."""
import sys

from . import main

sys.exit(main())
