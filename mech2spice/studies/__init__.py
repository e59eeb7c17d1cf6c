"""Measurements behind the reports: one module per study, each with ``SECTIONS`` and a function that measures
sections into a dict saved as JSON next to its report (reports/NAME.json).  mech2spice/reports/ only renders
those files into markdown and PNG, so `mech2spice report NAME --render` rebuilds a report without measuring.

What every study records about where it ran (machine, load, versions) and how it picks sections is in
`_common.py`, once.
"""

from ._common import SANDBOX, json_default, log, read_json, timed, write_json  # what reports/ reads through

__all__ = ["SANDBOX", "json_default", "log", "read_json", "timed", "write_json"]
