"""argparse value types shared by the benchmark families."""

import argparse


def _list_of(convert, what, minimum):
    def parse(text):
        try:
            values = [convert(v) for v in str(text).split(",") if v.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected comma-separated {what}, got {text!r}") from None
        if not values:
            raise argparse.ArgumentTypeError(f"expected at least one value, got {text!r}")
        bad = [v for v in values if not v >= minimum]
        if bad:
            raise argparse.ArgumentTypeError(f"values must be >= {minimum:g}, got {bad[0]}")
        return values
    return parse


def int_list(minimum=1):
    """'100,1000' -> [100, 1000]."""
    return _list_of(int, "integers", minimum)


def float_list(minimum=0.0):
    """'1e-6,1e-8' -> [1e-06, 1e-08]."""
    return _list_of(float, "numbers", minimum)


def at_least(minimum, convert=int):
    """A single number >= minimum."""
    def parse(text):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not value >= minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum:g}, got {value}")
        return value
    return parse


def add_number(parser, flag, minimum, default, what, convert=int):
    """Option ``flag``: one number >= minimum (``at_least``); help ``what (default D)``."""
    parser.add_argument(flag, type=at_least(minimum, convert), default=default,
                        help=f"{what} (default {default})")
