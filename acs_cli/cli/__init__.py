"""Typer command line (thin: parses options, calls the stages, prints)."""
