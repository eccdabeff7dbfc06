"""``python -m scrapcut_cli`` runs the ``scrapcut`` command."""

from scrapcut_cli.cli import main

if __name__ == "__main__":
    main()
