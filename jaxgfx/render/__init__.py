"""jaxgfx.render (see docs/)."""
