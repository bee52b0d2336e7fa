"""A toy CLI command, the whole of it: ``flexmodal modes-count MODES.csv`` prints how many modes each
configuration of a modal table holds (through the public API)."""

from flexmodal.cli.commands import command, register_command

NAME = "modes-count"


def _run(args) -> int:
    """count the modes of each configuration of a modal table

    Print one line per configuration of MODES.csv: its name and how many modes it holds.
    """
    import flexmodal as fm

    table = fm.read_table(args.table)
    for config in table.configs:
        print(f"{config} {len(table.freq_hz(config))}")
    return 0


def add(sub) -> None:
    p = command(sub, NAME, _run)
    p.add_argument("table", metavar="MODES.csv", help="modal table (docs/formats.md)")


register_command(NAME, add)
