"""Benchmarks: `omninav bench NAME` (cli/bench.py); each prints medians against a reference measured in the same run."""
