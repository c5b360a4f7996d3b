"""Evaluation: windowed open-loop predictions, one metrics schema, traces."""
