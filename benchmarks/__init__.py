"""Benchmarks and the generators of the figures and tables of the README and docs/ (see README.md here).

The scripts are run as scripts (`.venv/bin/python benchmarks/X.py`) and import their siblings by
plain name (`from measure import ...`); the tests import the two library modules as
`benchmarks.measure` and `benchmarks.memory`."""
