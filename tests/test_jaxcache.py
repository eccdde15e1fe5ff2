"""The CLI's persistent compilation cache location (env var override, XDG default, off)."""

from jaxgfx._jaxcache import compilation_cache_dir, enable_compilation_cache


def test_cache_dir_env(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXGFX_CACHE_DIR", str(tmp_path / "c"))
    assert compilation_cache_dir() == str(tmp_path / "c")
    for off in ("off", "0", ""):
        monkeypatch.setenv("JAXGFX_CACHE_DIR", off)
        assert compilation_cache_dir() is None
        assert enable_compilation_cache() is None
    monkeypatch.delenv("JAXGFX_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert compilation_cache_dir() == str(tmp_path / "xdg" / "jaxgfx" / "jax")
