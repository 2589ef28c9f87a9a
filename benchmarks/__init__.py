"""Benchmarks and the generators of the README's figures and tables (see README.md here).

The scripts are run as scripts (`.venv/bin/python benchmarks/X.py`) and import their siblings by
plain name (`from measure import ...`) and the tests' helpers as `tests.helpers` (measure.py puts
the checkout on sys.path)."""
