"""Configuration, torch-free: the closed choices as enums (`choices`), experiment TOML ->
typed, validated `Experiment` (`experiment`), and the numbers a user hands sysid, each kind
checked in one place (`checks`)."""
