"""Configuration: experiment TOML -> typed, validated `Experiment` (`experiment`), and the
numbers a user hands sysid checked, each kind in one place (`checks`). Torch-free."""
