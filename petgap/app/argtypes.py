"""Argument types for the command lines (``petgap``, ``petgap-post``).

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
