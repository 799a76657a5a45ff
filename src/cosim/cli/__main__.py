"""``python -m cosim.cli``: the `cosim` command."""
import sys

from cosim.cli import console

if __name__ == "__main__":  # importing this module (as the layers test does) runs nothing
    sys.exit(console())
