"""Configuration, torch-free: the closed choices as enums (`choices`) and experiment TOML ->
typed, validated `Experiment` (`experiment`)."""
