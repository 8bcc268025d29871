"""A module imported when first used, not when the test module is collected (``importlib.util.LazyLoader``).

``scipy.signal`` costs 0.7-1.3 s to import (after numpy; 3 runs). pytest-xdist collects every test module in every worker,
so a module-level import of it in the modules that compare against it was paid at every worker's start, whether or not that
worker ran them.
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType


def lazy_module(name: str) -> ModuleType:
    """Module ``name``, loaded at its first attribute access (already loaded: that module)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        raise ImportError(f"no module named {name!r}")
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module
