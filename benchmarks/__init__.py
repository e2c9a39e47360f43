"""Benchmarks of liesample (run `benchmarks/run.py`); not part of the installed package."""
