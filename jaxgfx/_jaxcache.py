"""JAX's persistent compilation cache for the CLI and the experiments (not for the library).

A cold ``jaxgfx calibrate`` spends most of its time compiling (2–5 s per new stack shape on
2 cores); with the cache a second run of the same shapes loads the compiled programs from disk.
Location: ``$JAXGFX_CACHE_DIR`` if set (``off``, ``0`` or empty disables the cache), else
``$XDG_CACHE_HOME/jaxgfx/jax`` (``~/.cache/jaxgfx/jax``). See docs/performance.md.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["enable_compilation_cache", "compilation_cache_dir"]


def compilation_cache_dir() -> str | None:
    """The cache directory the CLI would use, or ``None`` when disabled by the env var."""
    env = os.environ.get("JAXGFX_CACHE_DIR")
    if env is not None:
        return None if env.strip().lower() in ("", "0", "off", "none", "false") else env
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return str(Path(base) / "jaxgfx" / "jax")


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Point JAX's persistent compilation cache at ``path`` (default
    :func:`compilation_cache_dir`) and cache every program that took > 0.2 s to compile.
    Returns the directory, or ``None`` when disabled or not writable (then nothing changes)."""
    import jax

    d = path if path is not None else compilation_cache_dir()
    if d is None:
        return None
    try:
        os.makedirs(d, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", d)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return d
