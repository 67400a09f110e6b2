"""Reports for people: the paper's tables."""

from brachycal.reporting.tables import table_i, table_ii

__all__ = ["table_i", "table_ii"]
