"""`make bench`: the benchmarks (not installed with the package)."""
