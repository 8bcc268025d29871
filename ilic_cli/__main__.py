from ilic_cli.cli import run

run()
