"""End-to-end pipelines shared by the CLI and experiments/ (library code, no config files)."""
