"""Benchmarks and the generators of the figures and tables of the README and docs/ (see README.md here).

The scripts are run as scripts (`.venv/bin/python benchmarks/X.py`) and import their siblings by
plain name (`from measure import ...`) and the tests' helpers as `tests.helpers` (measure.py puts
the checkout on sys.path)."""
