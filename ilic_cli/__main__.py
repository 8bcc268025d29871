from ilic_cli.cli import main

main()
