"""The command line's command modules: each parses its commands' options, calls flexmodal.api and
prints; app.py builds the parser from their registry (cli.commands.COMMANDS)."""
