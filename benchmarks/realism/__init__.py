"""Realism measurements for docs/realism.md, one module per measurement; ``python -m
benchmarks.realism COMMAND`` runs them (the commands are listed in ``__main__``)."""
