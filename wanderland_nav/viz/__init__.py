"""Visualisation: top-down plots (matplotlib) and rerun logging. The only package that imports them."""
