"""Replicas and parameter sweeps on Dask, and their statistics."""
