"""Subcommands of the `vlr` CLI contributed by the core (registered as `vlr.commands`)."""
