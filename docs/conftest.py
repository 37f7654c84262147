"""pytest runs the pages of docs/ as doctests; the site's configuration and what its build generates are no tests."""

collect_ignore = ["conf.py"]
collect_ignore_glob = ["_build/*", "gallery/*", "api/*", "_ext/*"]
