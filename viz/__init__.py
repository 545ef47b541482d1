"""Rerun visualisation of runs (to come; nothing is implemented yet). The core never imports this package."""
