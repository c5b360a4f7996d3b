"""Storage: atomic files with the user's umask (`files`), completeness manifests
(`manifest`) and staged, all-or-nothing output directories (`staging`)."""
