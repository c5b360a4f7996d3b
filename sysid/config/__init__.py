"""Experiment configuration: TOML -> typed, validated `Experiment` (torch-free)."""
