"""pytest configuration of the suite; the shared helpers are in ``helpers.py``."""
