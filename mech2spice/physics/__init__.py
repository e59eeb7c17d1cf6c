"""The mechanical model: parameters and blocks, the gate and network builders, the envelope equations and their
steady states (docs/architecture.md)."""
from . import loaded as _loaded  # noqa: F401  adds the self-drive check to params.LOAD_CHECKS before any block loads
