"""Drive `surge predictor train|evaluate` without the coordinator's CLI (no zenoh on the device machine)."""
import argparse
import sys

from predictor.cli import add_parser

p = argparse.ArgumentParser(prog="surge")
sub = p.add_subparsers(dest="cmd")
add_parser(sub)
args = p.parse_args(sys.argv[1:])
sys.exit(args.func(args))
