"""Reports for people: the paper's tables and figures."""

from brachycal.reporting.tables import chain_summary, table_i, table_ii, table_iii, targeting_table

__all__ = ["chain_summary", "table_i", "table_ii", "table_iii", "targeting_table"]
