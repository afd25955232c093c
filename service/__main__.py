"""`python -m service`: the project's one command line (the same app as the installed `posedyn` script)."""

from service.cli import main

if __name__ == "__main__":
    main()
