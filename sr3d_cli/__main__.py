from sr3d_cli.cli import main

main()
