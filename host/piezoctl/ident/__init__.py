"""Offline identification of model parameters from recordings."""
