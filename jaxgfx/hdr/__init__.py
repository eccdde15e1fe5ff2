"""jaxgfx.hdr (see docs/)."""
