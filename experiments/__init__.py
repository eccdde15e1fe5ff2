"""Research scripts: ``python -m experiments.NAME --config configs/NAME.yaml``."""

# every `python -m experiments.NAME` shares JAX's persistent compilation cache with the CLI
# (docs/performance.md; JAXGFX_CACHE_DIR=off disables it)
from jaxgfx._jaxcache import enable_compilation_cache as _enable_cache

_enable_cache()
