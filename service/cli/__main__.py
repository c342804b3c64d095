"""``python -m service.cli``: the ``drt`` executable."""
from service.cli.main import console_main

console_main()
