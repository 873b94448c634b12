"""Synthetic recording sets with known, concealed physics: the forward simulator and its CLI."""
