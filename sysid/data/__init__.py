"""Processed recordings: runs and windows (`recordings`), the paper's datasets and test files
(`datasets`), the maneuver a log records (`scenario`), and reading a user's CSV with one
clear error (`csvfiles`)."""
