from posedyn.cli import main

main()
