"""`python -m posedyn`: the project's one command line, `service.cli` (this launcher is the one
place posedyn names service; no library module imports it)."""

from service.cli import main

if __name__ == "__main__":
    main()
