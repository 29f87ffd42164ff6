"""Metrics, evaluation runs and plots."""
