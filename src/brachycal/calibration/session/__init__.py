"""A session folder calibrated end to end, and the result file."""
