"""Research scripts: ``python -m experiments.NAME --config configs/NAME.yaml``."""
