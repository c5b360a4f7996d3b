"""Processed recordings: runs and windows (`recordings`), the paper's datasets and test files
(`datasets`), and reading a user's CSV with one clear error (`csvfiles`)."""
