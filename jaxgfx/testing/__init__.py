"""jaxgfx.testing (see docs/)."""
