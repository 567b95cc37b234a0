"""taplan's benchmark suite: ``python -m benchmarks`` (or ``taplan bench``) runs every bench_*.py."""
