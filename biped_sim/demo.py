"""``make demo``: until the node lands, a headless walking run with its summary."""
import sys

from .cli import main

if __name__ == "__main__":
    print("biped_sim demo: 10 s of walking with the reference controller (headless)")
    sys.exit(main(["simulate", "--duration", "10"]))
