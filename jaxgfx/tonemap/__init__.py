"""jaxgfx.tonemap (see docs/)."""
