"""`python -m diviewer.train.cli`: `diviewer train` on its own, the entry torchrun starts on each process::

    torchrun --standalone --nproc_per_node 4 -m diviewer.train.cli --data data/cornell --out runs/c4

The command itself is `diviewer.commands.train`; this module is only its documented ``-m`` name (tests/test_layout.py
lists it as the one entry point inside train/ that reaches the command line).
"""

import sys

if __name__ == "__main__":
    from diviewer.commands.train import main

    sys.exit(main())
