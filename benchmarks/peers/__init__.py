"""Reference solvers from other libraries, timed against sorofem by ``benchmarks/run.py``."""
