"""Glue to other libraries' formats and frameworks (Minari datasets)."""
