"""jaxgfx.io (see docs/)."""
