"""GDMLT's benchmarks (see __main__.py); not part of the product."""
