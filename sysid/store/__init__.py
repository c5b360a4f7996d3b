"""Storage: where outputs go and how they are written (atomic files, staged and sealed
directories, the output target every command checks)."""
