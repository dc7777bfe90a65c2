"""Readers of users' input files, one module per input, and the scenario-file assembler."""
