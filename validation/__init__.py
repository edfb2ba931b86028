"""Validation scripts: the packing chain against published data (run them as scripts)."""
