"""jaxgfx.color (see docs/)."""
