"""Argument types and parsers for the command lines (``petgap``, ``petgap-post``).

Each turns the text of one option into a value or raises
``argparse.ArgumentTypeError`` with a message naming the text and what is
allowed, which argparse prints as a usage error (exit 2).
"""
import argparse
import math


def number_in(low=0.0, high=math.inf, *, what="a positive number", low_open=True):
    """A float type accepting finite values in ``(low, high]`` (``[low, high]`` if not ``low_open``)."""
    def convert(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        above = value > low if low_open else value >= low
        if not (math.isfinite(value) and above and value <= high):
            raise argparse.ArgumentTypeError(f"{text} is not {what}")
        return value
    return convert


positive_float = number_in()


def positive_int(text):
    """An integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not positive")
    return value


class _RankParser(argparse.ArgumentParser):
    """An ArgumentParser that prints (usage, help, errors) only if ``rank`` is 0."""

    rank = 0

    def _print_message(self, message, file=None):
        if self.rank == 0:
            super()._print_message(message, file)


def root_parser(rank, **kwargs):
    """An ArgumentParser that prints only on rank 0 of an MPI job.

    Every rank parses the same command line and reaches the same verdict (exit
    or go on), but only rank 0 prints usage, help and errors, once.  The class
    is made per parser so that its subparsers (made from the same class) know
    the rank too.
    """
    return type("RankParser", (_RankParser,), {"rank": rank})(**kwargs)
