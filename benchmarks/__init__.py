"""Benchmarks: speed (and speed vs error) against peers, JSON out."""
