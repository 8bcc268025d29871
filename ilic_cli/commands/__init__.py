"""Subcommands; each module exposes ``command`` (a click command)."""
