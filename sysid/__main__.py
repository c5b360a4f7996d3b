"""``python -m sysid`` = the ``sysid`` command."""
from sysid.cli import main

main()
