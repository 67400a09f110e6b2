"""The pre-procedure check: null model, parts, test, record, update."""
