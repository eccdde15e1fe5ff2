"""jaxgfx.optim (see docs/)."""
