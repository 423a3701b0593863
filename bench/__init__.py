"""Benchmarks of the scheduling service: exact-solve times and evaluator throughput.

Run ``python -m bench.exact --help``; results land in ``bench/out/`` (gitignored)
and the published figures in ``docs/benchmarks.md``.
"""
