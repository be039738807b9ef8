"""Error measures, synthetic experiments with known truth (paper Sec. 6), the Adam
baseline, and what the benchmarks in ``benchmarks/`` share (:mod:`.benchmark_cases`)."""
