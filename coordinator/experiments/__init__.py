"""Experiment tooling: the evaluation harness, analysis, the paper protocol, reports, figures, sweeps and benchmarks.

The runtime never imports this package.
"""
