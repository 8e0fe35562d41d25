"""Plumbing shared by every layer: the registry class, typed errors, safe output writing, limits, shipped data paths, cone classes and per-frame arrays."""
