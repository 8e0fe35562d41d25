"""Benchmark targets for ``weather-gym bench``; ``benchmarks/*.py`` are thin scripts over these."""
