"""Storage: atomic files with the user's umask (`files`), completeness manifests
(`manifest`), staged, all-or-nothing output directories (`staging`) and the output target
every command checks and locks (`target`)."""
