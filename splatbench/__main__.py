"""``python -m splatbench``: the same command line as the ``splatbench`` script."""

from splatbench.cli import main

main()
