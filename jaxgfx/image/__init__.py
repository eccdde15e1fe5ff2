"""jaxgfx.image (see docs/)."""
