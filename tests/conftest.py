"""Test-suite settings: property tests draw the same examples on every machine and run (a CI run must see
what a developer saw; the fuzz tests also say so explicitly)."""

from hypothesis import settings

settings.register_profile("shipsense", derandomize=True)
settings.load_profile("shipsense")
