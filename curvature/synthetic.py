"""Synthetic shapes (placeholder until the module lands)."""
